"""Who hears a flight: the recorder, the other listeners, and the sources among them.

A :class:`FlightListener` gets ``begin``, ``rows`` per stream and ``end``. A listener that also
has ``streams()``, ``poll()`` and ``finish(path=)`` is a *source* (live identification,
:mod:`groundstation.flight.liveid`): it adds streams of its own, its polled rows go to the
recorder only, and a poll may ask to end the excitation. :class:`Listeners` calls them all on
the runner's thread; one that raises is dropped and reported through ``on_error`` (the
recorder's failure is the runner's to judge: it aborts the flight).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Protocol

from cfsession.schema import StreamSpec

__all__ = ["FlightListener", "Listeners"]

log = logging.getLogger(__name__)


class FlightListener(Protocol):
    """Receives a flight as it happens (the recorder, the live view, progress display)."""

    def begin(self, *, streams: Sequence[StreamSpec], metadata: Mapping[str, Any]) -> None: ...

    def rows(self, stream: str, rows: Sequence[tuple]) -> None:
        """Rows of ``stream``: tuples in the stream's field order, ``host_time`` first."""
        ...

    def end(self, *, summary: Mapping[str, Any]) -> None: ...


class Listeners:
    """The recorder first, then the other listeners; ``on_error(what, recorder, fatal)`` hears
    of one that raised (``what``: ``"Type.method failed (Exc: message)"``) after it was
    dropped; ``fatal``: the exception was no ``Exception`` (:attr:`escaping`)."""

    def __init__(self, *, recorder: FlightListener, others: Sequence[FlightListener],
                 on_error: Callable[[str, bool, bool], None]) -> None:
        self.recorder = recorder
        self.active: list[FlightListener] = [recorder, *others]
        self.sources: list[Any] = [x for x in others if hasattr(x, "poll")]
        self._on_error = on_error
        #: The first ``SystemExit``/``KeyboardInterrupt``/... a listener raised: the flight
        #: ends with its landing (``on_error`` with ``fatal=True``), then the runner re-raises it.
        self.escaping: BaseException | None = None

    @property
    def recording(self) -> bool:
        """Whether the recorder is still listening (it has not raised)."""
        return self.recorder in self.active

    def call(self, listener: FlightListener, method: str, **kw: Any) -> Any:
        """``listener.method(**kw)``; on an exception the listener is dropped, None returned.
        A ``BaseException`` that is no ``Exception`` (``SystemExit``) is kept in
        :attr:`escaping`, not raised through the flight: it would skip the landing."""
        try:
            return getattr(listener, method)(**kw)
        except BaseException as exc:
            self.active.remove(listener)
            if listener in self.sources:
                self.sources.remove(listener)
            what = f"{type(listener).__name__}.{method} failed ({type(exc).__name__}: {exc})"
            log.exception("listener %s", what)
            fatal = not isinstance(exc, Exception)
            if fatal and self.escaping is None:
                self.escaping = exc
            self._on_error(what, listener is self.recorder, fatal)
        return None

    def from_sources(self, method: str, **kw: Any) -> list[Any]:
        """The non-empty results of ``method`` of every source."""
        return [x for x in (self.call(s, method, **kw) for s in list(self.sources)) if x]

    def begin(self, *, streams: Sequence[StreamSpec], metadata: Mapping[str, Any]) -> None:
        """``begin`` of every listener but the recorder (the runner begins it first, alone:
        a flight that cannot be recorded is not flown)."""
        for listener in [x for x in self.active if x is not self.recorder]:
            self.call(listener, "begin", streams=streams, metadata=metadata)

    def poll(self) -> str:
        """Poll the sources, their rows to the recorder only. Returns a source's request to
        end the excitation ("" if none)."""
        reason = ""
        for batches, why in self.from_sources("poll"):
            for stream, rows in batches:  # the sources' own streams: into the file only
                if rows and self.recording:
                    self.call(self.recorder, "rows", stream=stream, rows=rows)
            reason = reason or why
        return reason

    def deliver(self, pending: Mapping[str, list[tuple]]) -> None:
        """``pending`` rows, per stream, to every listener."""
        for stream, rows in pending.items():
            for listener in list(self.active):
                self.call(listener, "rows", stream=stream, rows=rows)

    def end(self, *, summary: Mapping[str, Any]) -> None:
        for listener in list(self.active):
            self.call(listener, "end", summary=summary)
