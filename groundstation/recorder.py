"""The flight listener that records a session file (``docs/session-format.md``).

:class:`Recorder` implements :class:`groundstation.flight.FlightListener` on top of
:class:`groundstation.session.SessionWriter`: ``begin`` creates the file with every stream,
``rows`` queues rows (the writer appends them at most ``flush_interval`` s apart, crash-safe),
``end`` stores the summary, marks the file closed cleanly and compresses it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from groundstation.session import SessionWriter, check_writable
from groundstation.session_schema import StreamSpec

__all__ = ["Recorder", "session_path"]

log = logging.getLogger(__name__)


def session_path(*, out: str | Path, plan_name: str) -> Path:
    """A new file ``OUT/PLAN-YYYYmmddTHHMMSSZ.h5`` (UTC) (``-2``, ``-3`` ... if it exists), checked
    writable (one-line :class:`~groundstation.errors.SessionError` otherwise)."""
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())  # UTC, as start_time_iso
    base = Path(out) / f"{plan_name}-{stamp}"
    path, n = base.with_suffix(".h5"), 1
    while path.exists():
        n += 1
        path = base.with_name(f"{base.name}-{n}.h5")
    check_writable(path)
    return path


class Recorder:
    """Writes every row the flight runner hands out to the session file ``path``.

    ``metadata`` may carry ``start_time_ns`` (wall clock at the session's time origin).
    """

    def __init__(self, path: str | Path, *, flush_interval: float = 1.0,
                 compress_on_close: bool = True) -> None:
        self.path = Path(path)
        self._flush_interval = flush_interval
        self._compress = compress_on_close
        self._writer: SessionWriter | None = None

    def begin(self, *, streams: Sequence[StreamSpec], metadata: Mapping[str, Any]) -> None:
        meta = dict(metadata)
        start_ns = meta.pop("start_time_ns", None)
        self._writer = SessionWriter(self.path, streams=streams, metadata=meta,
                                     start_time_ns=start_ns, flush_interval=self._flush_interval,
                                     compress_on_close=self._compress)

    def rows(self, stream: str, rows: Sequence[tuple]) -> None:
        if self._writer is None:
            raise RuntimeError("Recorder.rows() before begin()")
        self._writer.extend(stream, rows)

    def counts(self) -> dict[str, int]:
        """Rows per stream so far (written plus buffered)."""
        return {} if self._writer is None else self._writer.counts()

    def end(self, *, summary: Mapping[str, Any]) -> None:
        if self._writer is None:
            return
        duration = summary.get("duration_s")
        self._writer.close(duration_s=None if duration is None else float(duration),
                           summary=summary)
        log.info("session written: %s", self.path)
