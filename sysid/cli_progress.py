"""Progress of long ``sysid`` commands (sweep, batch) on stderr.

On a terminal: a bar with counts, elapsed time and ETA. Not on a terminal (a log file, CI): one
plain line each time another tenth of the work is done, with the ETA, and one saying "done" when
the work has ended (not at 100 % of a total that may still grow), so logs stay short and
readable. Quiet (``--json``) prints nothing.
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


@contextmanager
def progress(label: str, *, total: int, quiet: bool = False,
             stream: TextIO | None = None) -> Iterator[Callable[..., None]]:
    """Yield ``update(done, total=None)``; a bar on a TTY, plain periodic lines otherwise. A
    ``total`` given to ``update`` replaces the first one (work that grew: a selection whose
    grid grows, :mod:`sysid.growth`)."""
    out = stream if stream is not None else sys.stderr
    if quiet:
        yield lambda _done, _total=None: None
        return
    if out.isatty():
        with Progress(label, BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                      "eta", TimeRemainingColumn(), console=Console(file=out)) as bar:
            task = bar.add_task(label, total=total)
            yield lambda done, total=None: bar.update(task, completed=done, total=total)
        return
    t0 = time.monotonic()
    shown, last = 0, [0, total]

    def line(done: int, tail: str) -> None:
        print(f"{label}: {done}/{total} ({100 * done / max(total, 1):.0f} %), "
              f"{time.monotonic() - t0:.0f} s, {tail}", file=out, flush=True)

    def update(done: int, new_total: int | None = None) -> None:
        nonlocal shown, total
        if new_total is not None and new_total != total:  # count on against the new total
            total = new_total
            shown = min(shown, int(done / max(total, 1) / STEP + 1e-9) - 1)
        last[:] = [done, total]
        step = int(done / max(total, 1) / STEP + 1e-9)
        if done >= total or step <= shown:  # "done" only when the work ends: it may grow
            return
        shown = step
        eta = (time.monotonic() - t0) / done * (total - done) if done else float("nan")
        line(done, f"eta {eta:.0f} s")

    yield update
    line(last[0], "done")
