"""Progress of long ``sysid`` commands (sweep, batch) on stderr.

On a terminal: a bar with counts, elapsed time and ETA. Not on a terminal (a log file, CI): one
plain line each time another tenth of the work is done, with the ETA, and one saying "done" when
the work has ended (not at 100 % of a total that may still grow), so logs stay short and
readable, and a line with the detail the work gives (a batch's group and its models) when 30 s
passed without one. Quiet (``--json``) prints nothing.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TextIO

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

__all__ = ["progress"]

#: Plain lines are printed every this fraction of the work.
STEP = 0.1
#: ... and, with a detail to give, at least this often (seconds).
HEARTBEAT_S = 30.0


@contextmanager
def progress(label: str, *, total: int, quiet: bool = False, stream: TextIO | None = None,
             heartbeat_s: float | None = None,
             clock: Callable[[], float] = time.monotonic) -> Iterator[Callable[..., None]]:
    """Yield ``update(done=None, total=None, *, detail=None)``; a bar on a TTY, plain periodic
    lines otherwise. A ``total`` given to ``update`` replaces the first one (work that grew: a
    selection whose grid grows, :mod:`sysid.growth`). ``detail`` says where the current unit
    of work is (a batch's group: ``a1: 120/400 models``): on the bar's label, and not on a
    terminal a line with it once ``heartbeat_s`` (:data:`HEARTBEAT_S`) passed without one,
    so a long unit shows it is alive. ``done=None`` keeps the count."""
    out = stream if stream is not None else sys.stderr
    heartbeat_s = HEARTBEAT_S if heartbeat_s is None else heartbeat_s
    if quiet:
        yield lambda _done=None, _total=None, **_kw: None
        return
    if out.isatty():
        with Progress("{task.description}", BarColumn(), MofNCompleteColumn(),
                      TimeElapsedColumn(), "eta", TimeRemainingColumn(),
                      console=Console(file=out)) as bar:
            task = bar.add_task(label, total=total)

            def bar_update(done: int | None = None, total: int | None = None, *,
                           detail: str | None = None) -> None:
                bar.update(task, completed=done, total=total,
                           description=None if detail is None else f"{label} ({detail})")

            yield bar_update
        return
    t0 = clock()
    shown, last, said = 0, [0, total], [t0]

    def line(done: int, tail: str) -> None:
        said[0] = clock()
        print(f"{label}: {done}/{total} ({100 * done / max(total, 1):.0f} %), "
              f"{said[0] - t0:.0f} s, {tail}", file=out, flush=True)

    def update(done: int | None = None, new_total: int | None = None, *,
               detail: str | None = None) -> None:
        nonlocal shown, total
        done = last[0] if done is None else done
        if new_total is not None and new_total != total:  # count on against the new total
            total = new_total
            shown = min(shown, int(done / max(total, 1) / STEP + 1e-9) - 1)
        last[:] = [done, total]
        step = int(done / max(total, 1) / STEP + 1e-9)
        if done >= total or step <= shown:  # "done" only when the work ends: it may grow
            if detail is not None and clock() - said[0] >= heartbeat_s:
                line(done, detail)
            return
        shown = step
        eta = (clock() - t0) / done * (total - done) if done else float("nan")
        line(done, f"eta {eta:.0f} s")

    yield update
    line(last[0], "done")
