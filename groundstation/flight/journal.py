"""What a flight records as it goes, between the runner's thread and its listeners.

Rows are kept per stream in :attr:`Journal.pending` (setpoints, phases, events, log rows, link
rows: appending is all the runner does while a setpoint is due) until :meth:`Journal.dispatch`
polls the sources and hands every pending row to the listeners (:class:`Listeners`, the recorder
first). Times are flight time: seconds on the flight clock since the journal began.

**Causes.** The first cause recorded (:meth:`Journal.cause`) is the flight's abort cause; later
ones are recorded as events "during the abort" (and end the descent: the operator's second
signal); :meth:`Journal.trouble` (a full disk, a failed recording) never ends a descent. A listener
that raises is dropped with an event and the flight goes on; the recorder raising is trouble (a
flight that is not recorded aborts).
"""

from __future__ import annotations

import logging
from collections import defaultdict
from collections.abc import Sequence

from cfsession.writer import event_rows
from groundstation.flight.clock import Clock
from groundstation.flight.listeners import FlightListener, Listeners

__all__ = ["Journal"]

log = logging.getLogger("groundstation.flight.runner")  # events are the runner's: logged as its
_LOG_LEVELS = {"error": logging.ERROR, "warning": logging.WARNING}
"""How an event of each level is logged (any other level: ``INFO``); ``groundstation fly``
shows warnings and errors on standard error."""


class Journal:
    """Pending rows, events and causes of one flight (module docstring)."""

    def __init__(self, *, clock: Clock, recorder: FlightListener,
                 listeners: Sequence[FlightListener]) -> None:
        self.clock = clock
        self.origin = clock.now()
        self.pending: dict[str, list[tuple]] = defaultdict(list)
        self.causes: list[str] = []
        self.end_excitation = ""  # a source's request to end the excitation
        self.landed = False  # the plan flown through and the stop sent (Commander.land)
        self.recording_lost_s: float | None = None  # flight time the recorder raised at
        self.listeners = Listeners(recorder=recorder, others=listeners,
                                   on_error=self._listener_failed)

    def now(self) -> float:
        """Flight time, s."""
        return self.clock.now() - self.origin

    def event(self, text: str, *, level: str = "info", source: str = "runner") -> None:
        log.log(_LOG_LEVELS.get(level, logging.INFO), "%s: %s", source, text)
        self.pending["events"].extend(event_rows(t=self.now(), text=text, level=level,
                                                 source=source))

    def cause(self, text: str, *, level: str = "error") -> None:
        """A reason to abort: the first is the flight's cause, all are events (``safety``)."""
        self.causes.append(text)
        self.event(text if len(self.causes) == 1 else f"during the abort: {text}",
                   level=level, source="safety")

    def stop_request(self, text: str, *, level: str = "error") -> None:
        """An operator's signal: the flight's cause while it flies; after the landing (the stop
        delivered over a link still up, the file's tail recording) an event, since the flight
        was complete (a Ctrl-C then made a landed flight "aborted", exit 2). A lost link is
        always a cause: its report can come after a stop it kept from the vehicle."""
        if self.landed and not self.causes:
            self.event(f"after landing: {text}", level=level, source="safety")
        else:
            self.cause(text, level=level)

    def trouble(self, text: str) -> None:
        """A reason to end the flight that is no reason to hurry an abort already under way (a
        disk that refuses room, a recording that failed): the flight's cause when it is the
        first, else an event "during the abort". A new cause ends the descent at once (the
        operator's second signal); this never does, so the landing the reserve was kept for
        is flown. After the landing (the motors stopped, the file's tail recording) it is an
        event too: the flight was not aborted."""
        if self.causes:
            self.event(f"during the abort: {text}", level="error", source="safety")
        elif self.landed:
            self.event(f"after landing: {text}", level="error", source="safety")
        else:
            self.cause(text)

    def phase(self, *, phase_id: int, name: str, kind: str, planned_s: float) -> None:
        self.pending["phases"].append((self.now(), phase_id, name.encode()[:32],
                                       kind.encode()[:16]))
        self.event(f"phase {name} ({kind}) starts, {planned_s:g} s planned")

    def _listener_failed(self, what: str, recorder: bool, fatal: bool) -> None:
        if fatal and not recorder:  # SystemExit and the like: the program ends, after landing
            self.trouble(f"{what}: the flight ends")
        elif recorder:
            self.recording_lost_s = self.now()
            self.trouble(f"recording failed: {what}")
        else:
            self.event(f"{what}; listener dropped, flight continues", level="error")

    def dispatch(self) -> None:
        """The sources polled, then every pending row (events of a failed poll included)."""
        reason = self.listeners.poll()  # always polled: the sources' rows are recorded
        self.end_excitation = self.end_excitation or reason
        pending, self.pending = self.pending, defaultdict(list)
        self.listeners.deliver(pending)
