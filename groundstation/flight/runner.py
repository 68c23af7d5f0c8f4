"""The flight runner: stream a plan's setpoints on a drift-free schedule, record, stay safe.

:func:`fly_plan` connects (:mod:`groundstation.flight.link`), checks the TOC and the battery,
records the flight through :class:`~groundstation.recorder.Recorder` and any other
:class:`FlightListener`, and returns a :class:`FlightResult` (session path, summary, abort cause).
The parts it drives, on its one thread:

==========================================  ===============================================
:mod:`~groundstation.flight.blocks`         the log blocks, checked against the TOC
:mod:`~groundstation.flight.telemetry`      cflib's queue drained; rate and silence watches
:mod:`~groundstation.flight.commander`      setpoints out on the schedule; landing, abort, stop
:mod:`~groundstation.flight.journal`        rows, events and causes handed to the listeners
==========================================  ===============================================

**Schedule.** Setpoint :math:`k` is due at :math:`t_k = t_0 + k / f_s` on the flight clock
(:func:`groundstation.flight.clock.clock_for_uri`: the simulation's clock for ``sim://``), never
:math:`t_{k-1} + 1/f_s`, so lateness never accumulates. One setpoint of thrust 0 at
:math:`t_0 - 1/f_s` releases the firmware's thrust lock; the stop setpoint follows one period
after the last one.

**Threads.** cflib's callbacks only put tuples on a :class:`queue.SimpleQueue` (the one hand-off,
see :mod:`groundstation.flight.link`); this runner's thread sends, drains the queue, checks limits
and feeds the listeners, in that order, so listener work never delays a setpoint.

**Altitude hold.** With a plan's ``[altitude_hold]`` the altitude estimate is logged in an extra
block and :class:`~groundstation.plan.altitude.AltitudeHold` trims the thrust of each setpoint in
the held phases; the setpoints stream records the thrust as sent.

**Safety.** SIGINT, SIGTERM, SIGHUP, SIGQUIT and SIGTSTP (handlers installed while flying,
restored after: :func:`~groundstation.flight.realtime.signal_handlers`), link loss (cflib's, or
no log packet for :data:`~groundstation.flight.telemetry.LINK_SILENCE_S` = 0.5 s of flight time
while flying), a setpoint more than :data:`SETPOINT_LATE_S` late (the host suspended or the
runner's thread held up: the missed setpoints are never sent as a burst), an exception in the
runner, a measured rate beyond :class:`RateLimits`, a setpoint
that is not finite (NaN or inf is never sent), a battery below ``vehicle.min_vbat`` or a vehicle
its supervisor locked or that is upside down (``supervisor.info``) at take-off
each record an event (source ``safety``) and end with the stop setpoint; if the plan's
``on_abort`` is ``descend`` and the link is up, the
:meth:`~groundstation.plan.schedule.Schedule.abort_schedule` descent streams first at the same rate,
so there is never more than one period without a setpoint (never after a link loss: no
telemetry, no descent). The stop setpoint is delivered before the link closes on every path,
the abort path failing included (:meth:`~groundstation.flight.link.Link.deliver_stop`), and
recorded as a row and an event. The summary counts the log packets missing up to the moment the link
closed, so a link dead before the end shows as dropped packets. A listener that raises is dropped
(with an event); the flight goes on, unless what it raised is no ``Exception`` (``SystemExit``):
that is the cause, the flight lands, and the exception is raised once the file is closed
(or returned in the result: ``fly_plan(reraise=False)``).
Without its recorder the flight aborts; a session file that cannot be created (folder, name,
no room) is a one-line error before take-off, nothing flown. A disk that fills (or the file
size limit) is a cause too, told by the recorder while its reserve still holds the landing;
where the session ended up after a moved or deleted folder, or that it holds part of the
flight or was lost, goes into the summary (``file``, ``file_notes``, ``file_error``) and the
result (:meth:`_Runner.file_outcome`).

**Sources.** A listener with ``streams()``, ``poll()``, ``finish(path=)``
(:mod:`groundstation.flight.listeners`; live identification, :mod:`groundstation.flight.liveid`)
adds streams, polled after each setpoint (rows to the recorder only; a request to end the
excitation: the plan goes on after its last excitation phase, no period skipped), and is
finished after the stop; its entries join the summary.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from cfsession.writer import standard_streams
from groundstation.errors import FlightAborted, GroundStationError, SessionError
from groundstation.flight.blocks import (
    ARMED_BIT,
    AUTO_ARM_BIT,
    BATTERY_BLOCK,
    CAN_ARM_BIT,
    CAN_FLY_BIT,
    CRASHED_BIT,
    LOCKED_BIT,
    LOW_POWER,
    PM_STATE,
    SUPERVISOR_INFO,
    TUMBLED_BIT,
    altitude_block_period,
    flight_blocks,
    positions,
)
from groundstation.flight.clock import clock_for_uri
from groundstation.flight.commander import SETPOINT_LATE_S, Commander, finite
from groundstation.flight.drivers import install_drivers
from groundstation.flight.journal import Journal
from groundstation.flight.link import open_link
from groundstation.flight.listeners import FlightListener
from groundstation.flight.params import (
    ParamChange,
    check_parameters,
    restore_after_flight,
    set_for_flight,
)
from groundstation.flight.realtime import prompt_thread_switches, signal_handlers
from groundstation.flight.result import FlightResult, block_summary, setpoint_summary
from groundstation.flight.safety import RateLimits
from groundstation.flight.telemetry import Telemetry
from groundstation.flight.uri import DEFAULT_URI, check_uri
from groundstation.plan import Plan, Schedule, load_plan
from groundstation.plan.altitude import AltitudeHold
from groundstation.recorder import Recorder, session_path

__all__ = ["ARM_WITHIN_S", "SETPOINT_LATE_S", "FlightListener", "FlightResult", "RateLimits",
           "altitude_block_period", "block_summary", "fly_plan"]

log = logging.getLogger(__name__)

ARM_WITHIN_S = 2.0
"""With ``arm``: flight time the vehicle has to report itself armed after the request (the
battery block that logs ``supervisor.info`` comes every 0.5 s)."""


class _Runner:
    """One flight; see the module docstring. Use :func:`fly_plan`."""

    def __init__(self, *, plan: Plan, schedule: Schedule, uri: str, recorder: Recorder,
                 listeners: Sequence[FlightListener], limits: RateLimits,
                 connect_timeout_s: float, tick_hook: Callable[[int], None] | None,
                 tag: str = "", reraise: bool = True, arm: bool = False) -> None:
        self.plan, self.schedule, self.uri, self.tag = plan, schedule, uri, tag
        self.reraise, self.arm = reraise, arm
        self.recorder, self.limits, self.tick_hook = recorder, limits, tick_hook
        self.connect_timeout_s = connect_timeout_s
        self.cancel = threading.Event()  # set by request_abort: also cancels a connect
        install_drivers()  # a link driver may bring its own clock (sim://): register it first
        self.clock = clock_for_uri(uri)
        self.journal = Journal(clock=self.clock, recorder=recorder, listeners=listeners)
        recorder.on_trouble = self.journal.trouble  # a full disk: land while the reserve lasts
        # its inbox is the only hand-off from cflib's threads: log rows, link events, aborts
        self.telemetry = Telemetry(journal=self.journal, limits=limits)
        self.start_ns = time.time_ns()
        self.out: Commander | None = None  # the setpoints, once connected
        self.cut: dict[str, Any] = {}  # what a source's request to end the excitation skipped
        self.n_scheduled = 0
        self.next_tick = 0  # the next setpoint of the plan to send (an abort descends from it)
        self.t_close = math.nan  # flight time the link was closed (log packets end there)
        self.block_periods: dict[str, float] = {}
        cfg = schedule.altitude_hold
        self.hold = AltitudeHold(cfg, period_s=schedule.period) if cfg else None
        self.params: list[ParamChange] = []  # the plan's [parameters], once written

    def request_abort(self, cause: str) -> None:
        """Thread- and signal-safe: the runner aborts at its next deadline (or stops
        connecting at once)."""
        self.cancel.set()
        self.telemetry.inbox.put(("abort", self.clock.now(), cause))

    # ------------------------------------------------------------------ the flight
    def preflight(self) -> bool:
        """Wait for every log block and a battery reading; refuse a low battery, and a
        vehicle its supervisor has locked or that is upside down (``supervisor.info``)."""
        journal, telemetry = self.journal, self.telemetry
        names = list(self.block_periods)
        give_up = time.monotonic() + max(3.0, self.connect_timeout_s / 2)
        t = self.clock.now()
        while not journal.causes:
            missing = [n for n in names if not telemetry.delivered[n]]
            if not missing and (telemetry.vbat is not None or BATTERY_BLOCK[0] not in names):
                break
            if time.monotonic() > give_up:
                journal.cause(f"log blocks {missing} delivered nothing; check the link")
                return False
            t += self.schedule.period
            telemetry.wait(t)
            journal.dispatch()
        if journal.causes:
            return False
        v, vbat, bits = self.schedule.vehicle, telemetry.vbat, telemetry.supervisor
        if vbat is not None and vbat < v.min_vbat:
            journal.cause(f"battery {vbat:.2f} V below vehicle.min_vbat = {v.min_vbat:g} V: "
                          "refusing to take off; charge or swap the battery")
            return False
        if telemetry.pm_state == LOW_POWER:
            battery = "" if vbat is None else f"battery {vbat:.2f} V, "
            journal.cause(f"the Crazyflie reports low power (pm.state 3: {battery}below "
                          "pm.lowVoltage for 5 s): refusing to take off; charge or swap the "
                          "battery")
            return False
        if bits is not None and bits & LOCKED_BIT:  # it would "fly" with its motors at 0
            journal.cause(f"the Crazyflie is locked (supervisor.info 0x{bits:04x}): its "
                          "supervisor stopped it (a commander watchdog timeout in flight, an "
                          "emergency stop or a crash) and keeps it so until restarted; "
                          "refusing to take off; power-cycle it (the SITL firmware: restart "
                          "groundstation sim --firmware)")
            return False
        if bits is not None and bits & TUMBLED_BIT:
            journal.cause(f"the Crazyflie is upside down (supervisor.info 0x{bits:04x}): "
                          "refusing to take off; set it level")
            return False
        if bits is not None and not bits & ARMED_BIT and not self._armed(bits):
            return False
        if bits is None and self.arm:
            self._arm_unconfirmed()
        battery = "no battery reading" if vbat is None else f"battery {vbat:.2f} V"
        journal.event(f"preflight ok: {battery}, log blocks {names} running")
        return True

    def _armed(self, bits: int) -> bool:
        """A vehicle that is not armed would "fly" the plan with its motors at 0: with ``arm``
        (``fly --arm``) ask it to arm and wait, at most :data:`ARM_WITHIN_S` of flight time,
        for ``supervisor.info`` logged after the request to say armed and able to fly; else
        the cause, nothing flown. One that cannot be armed now (bit 0 clear: crashed, its
        pre-flight checks not passed; the firmware drops the request) is refused at once, and
        one that locks while arming is refused as locked."""
        journal, telemetry = self.journal, self.telemetry
        info = f"supervisor.info 0x{bits:04x}"
        if not bits & CAN_ARM_BIT:  # the firmware refuses an arming request now: say why
            why = ("crashed: send it a crash recovery request or restart it"
                   if bits & CRASHED_BIT else "its pre-flight checks have not passed (set it "
                   "level and still, or restart it)")
            journal.cause(f"the Crazyflie is not armed and cannot be armed ({info}): {why}; "
                          "refusing to take off")
            return False
        if not self.arm:
            itself = ("it arms itself once its pre-flight checks pass" if bits & AUTO_ARM_BIT
                      else "it does not arm itself (a Crazyflie Brushless)")
            journal.cause(f"the Crazyflie is not armed ({info}): its motors would not run; "
                          f"{itself}; fly --arm arms it before take-off")
            return False
        asked = journal.now()
        self.out.link.request_arming()
        journal.event("arming requested (fly --arm)")
        t = self.clock.now()
        while journal.now() - asked < ARM_WITHIN_S and not journal.causes:
            t += self.schedule.period
            telemetry.wait(t)
            journal.dispatch()
            bits = telemetry.supervisor or 0
            fresh = telemetry.supervisor_t > asked
            if fresh and bits & LOCKED_BIT:
                journal.cause(f"the Crazyflie locked while arming (supervisor.info "
                              f"0x{bits:04x}): refusing to take off; power-cycle it")
                return False
            if fresh and bits & ARMED_BIT and bits & CAN_FLY_BIT:
                journal.event(f"armed (supervisor.info 0x{bits:04x})")
                return True
        if not journal.causes:
            journal.cause(f"the Crazyflie did not arm within {ARM_WITHIN_S:g} s of the request "
                          f"(supervisor.info 0x{telemetry.supervisor or 0:04x}); refusing to "
                          "take off")
        return False

    def _arm_unconfirmed(self) -> None:
        """``arm`` on a firmware whose log TOC has no ``supervisor.info`` (older firmware): its
        supervisor state cannot be read, so neither can the arming. The request is sent all
        the same (cflib falls back to the legacy platform channel there) and the flight goes
        on, with a warning that says so: the firmware that needs arming reports its state, and
        one that did not arm would "fly" the plan with its motors at 0."""
        self.out.link.request_arming()
        self.journal.event(f"fly --arm: no {SUPERVISOR_INFO} in the log TOC, the firmware "
                           "reports no supervisor state: arming requested but it cannot be "
                           "confirmed; flying on (a vehicle that did not arm keeps its motors "
                           "at 0)", level="warning")

    def fly(self) -> int:
        """Unlock, then every scheduled setpoint; returns the next unsent tick."""
        s, k, out, journal, telemetry = self.schedule, 0, self.out, self.journal, self.telemetry
        out.t_first = self.clock.now() + s.period
        out.send((0.0, 0.0, 0.0, 0), phase_id=-1, tick=-1)  # releases the thrust lock
        telemetry.flying = True
        telemetry.last_log = max(telemetry.last_log, journal.now())  # the silence watch starts
        current = -1
        while k < len(s) and not journal.causes:
            telemetry.wait(out.deadline(k))
            late = out.lateness(k)
            if late > SETPOINT_LATE_S and not journal.causes:  # a backlog is never sent
                journal.cause(f"setpoint {k} is {late:.2f} s late: the ground station was held "
                              "up (suspended, or a write or listener blocked it); the "
                              "Crazyflie's watchdog levels out after 0.5 s without a setpoint "
                              "and stops the motors after 2 s")
            if journal.causes:
                break
            if self.tick_hook is not None:
                self.tick_hook(k)
            ph = s.phase_at(k)
            if journal.end_excitation and ph.kind == "excitation" and not self.cut:
                end = max(p.end_tick for p in s.phases if p.kind == "excitation")
                out.t_first -= (end - k) * s.period  # setpoint `end` goes out now
                self.cut = {"at_s": round(journal.now(), 3), "reason": journal.end_excitation,
                            "skipped_s": round((end - k) * s.period, 3)}
                journal.event(f"excitation ended {self.cut['skipped_s']:.1f} s early: "
                              f"{journal.end_excitation}")
                k, ph = end, s.phase_at(end)
            if ph.id != current:
                current = ph.id
                journal.phase(phase_id=ph.id, name=ph.name, kind=ph.kind, planned_s=ph.duration)
                telemetry.landing = ph.kind == "landing"  # low power there: land as planned
            sp = self._trimmed(s.setpoint(k), kind=ph.kind)
            if not finite(sp):
                journal.cause(f"setpoint {k} (phase {ph.name}) is not finite "
                              f"({', '.join(f'{v:g}' for v in sp)}); not sent")
                break
            out.send(sp, phase_id=ph.id, tick=k)
            self.n_scheduled += 1
            k = self.next_tick = k + 1  # an exception below still descends from here
            journal.dispatch()
        return k

    def _trimmed(self, sp: tuple[float, float, float, int], *, kind: str
                 ) -> tuple[float, float, float, int]:
        """The setpoint with the altitude-hold trim added to its thrust (within the limits)."""
        if self.hold is None:
            return sp
        active = kind in self.hold.config.kinds
        altitude_m = self.telemetry.altitude_m
        if active and altitude_m is None:
            self.journal.cause(f"altitude hold: no {self.hold.config.variable} sample yet")
        trim = self.hold.update(z=altitude_m, active=active)
        if not trim:
            return sp
        v = self.schedule.vehicle
        roll, pitch, yaw_rate, thrust = sp
        return roll, pitch, yaw_rate, min(max(thrust + trim, v.thrust_min), v.thrust_max)

    def run(self) -> FlightResult:
        journal, listeners = self.journal, self.journal.listeners
        link = open_link(uri=self.uri, clock=self.clock, post=self.telemetry.inbox.put,
                         timeout_s=self.connect_timeout_s, cancel=self.cancel)
        out = self.out = Commander(link=link, journal=journal, telemetry=self.telemetry,
                                   schedule=self.schedule)
        k, begun = 0, False
        try:
            hold = self.schedule.altitude_hold
            blocks = flight_blocks(toc_type=link.toc_type, setpoint_period_s=self.schedule.period,
                                   altitude_variable=hold.variable if hold else None,
                                   warn=lambda text: journal.event(text, level="warning"))
            self.block_periods = {b.name: b.period_s for b in blocks}
            self.telemetry.supervisor_at = positions(blocks, SUPERVISOR_INFO)
            self.telemetry.pm_state_at = positions(blocks, PM_STATE)
            changes = check_parameters(link.cf, self.plan.parameters)  # before any file
            meta = {**link.metadata(), **self._plan_metadata(),
                    **({"plan_parameters": {c.name: {"value": c.value, "was": c.old}
                                            for c in changes}} if changes else {})}
            streams = [*(b.spec() for b in blocks), *standard_streams()]
            own = [spec for specs in listeners.from_sources("streams") for spec in specs]
            try:  # the file first: a flight that cannot be recorded is not flown
                self.recorder.begin(streams=[*streams, *own], metadata=meta)
            except (GroundStationError, SessionError) as exc:
                raise SessionError(f"{exc}; nothing flown") from None
            except Exception as exc:
                log.debug("recorder.begin failed", exc_info=True)
                raise FlightAborted(f"cannot record to {self.recorder.path} "
                                    f"({type(exc).__name__}: {exc}); nothing flown") from None
            begun = True
            listeners.begin(streams=streams, metadata=meta)
            link.start_blocks(blocks)
            try:
                if self.write_params(changes) and self.preflight():
                    k = self.fly()
            except Exception as exc:
                log.exception("flight runner error")
                journal.cause(f"runner error: {type(exc).__name__}: {exc}")
                k = self.next_tick  # the descent starts at the plan's thrust there, not tick 0
            try:
                if journal.causes:
                    out.abort(k)
                else:
                    out.land(k)
                out.tail()
            except Exception as exc:  # the stop follows in the finally clause
                log.exception("abort path failed")
                journal.cause(f"runner error while stopping: {type(exc).__name__}: {exc}")
        finally:  # each step guarded: one that raises never skips the file's end
            if begun and not out.stopped:  # every path out ends with the stop, kept fed
                out.last_stop()
                self._guarded("feeding the stop setpoint", out.tail)
            if self.params:
                self._guarded("restoring the parameters", lambda: restore_after_flight(
                    link.cf, self.params, event=journal.event,
                    link_up=not (out.link_down or link.stuck)))
            self.t_close = journal.now()
            self._guarded("closing the link", link.close)
            self._guarded("collecting the telemetry", self.telemetry.collect)
            finished = (self._guarded("finishing the sources", lambda: listeners.from_sources(
                "finish", path=self.recorder.path)) or [] if begun else [])
            summary = self._guarded("the summary", self.summary) or {
                **self.outcome(), "error": "the summary failed (its error is an event)"}
            for entries in finished:
                summary.update(entries)
            if begun:
                self._guarded("recording the last rows", journal.dispatch)
                listeners.end(summary=summary)
                if not listeners.recording:  # dropped after raising: close what it has
                    self.recorder.end(summary=summary)
        cause = journal.causes[0] if journal.causes else ""
        if begun:
            cause = self.file_outcome(summary, cause)
        result = FlightResult(path=self.recorder.path, summary=summary, cause=cause,
                              escaped=listeners.escaping)
        if listeners.escaping is not None and self.reraise:  # landed and recorded: now it
            raise listeners.escaping  # may end the program
        return result

    def _guarded(self, what: str, step: Callable[[], Any]) -> Any:
        """``step()``, or None after an event saying it failed (logged with its traceback):
        the steps after the stop must all run, the file's end last."""
        try:
            return step()
        except Exception as exc:
            log.exception("%s failed", what)
            self.journal.event(f"{what} failed after the stop ({type(exc).__name__}: {exc})",
                               level="error")
            return None

    def file_outcome(self, summary: dict[str, Any], cause: str) -> str:
        """The session file as it ended up, into ``summary``: ``file`` (its name now: a folder
        moved while flying moves it; ``None`` when lost), ``file_notes`` (what happened to it),
        ``file_error`` (one line: lost, or holding only part of a flight that was not aborted).
        Returns the abort cause, told when the file holds only part of the flight."""
        rec = self.recorder
        summary["file"] = None if rec.error else str(rec.path)
        if rec.notes:
            summary["file_notes"] = list(rec.notes)
        partial = ""
        if rec.saved_until is not None:
            until = math.floor(rec.saved_until * 10) / 10  # rows up to then at least
            partial = (f"the file holds the flight up to {until:.1f} s only"
                       f"{f' ({rec.trouble})' if rec.trouble and not cause else ''}")
        elif self.journal.recording_lost_s is not None:  # the recorder raised, was dropped
            until = math.floor(self.journal.recording_lost_s * 10) / 10
            partial = (f"the file holds the flight up to about {until:.1f} s only, not its "
                       "stop: recording failed then")
        if rec.error:
            summary["file_error"] = rec.error
        elif partial and not cause:
            summary["file_error"] = f"{rec.path}: {partial}"
        return f"{cause}; {partial}" if cause and partial else cause

    def write_params(self, changes: list[ParamChange]) -> bool:
        """The plan's ``[parameters]`` written (:func:`~.params.set_for_flight`); False after a
        cause (nothing is flown then). Restored after the stop, even if only some were
        written."""
        self.params = changes
        failed = set_for_flight(self.out.link.cf, changes, event=self.journal.event)
        if failed:
            self.journal.cause(failed)
        return not failed

    def _plan_metadata(self) -> dict[str, Any]:
        s = self.schedule
        return {
            "start_time_ns": self.start_ns,
            "plan_name": self.plan.name,
            "tag": self.tag,
            "plan_text": self.plan.text,
            "phase_table": [p.to_dict() for p in s.phases],
            "setpoint_rate_hz": s.rate_hz,
            "rate_limits": {"max_rate_deg_s": self.limits.max_rate_deg_s,
                            "samples": self.limits.samples},
        }

    def outcome(self) -> dict[str, Any]:
        """The summary's first entries: file, plan, uri, duration, aborted and cause (what a
        summary that failed still holds)."""
        journal = self.journal
        end = self.t_close if math.isfinite(self.t_close) else journal.now()
        return {
            "file": str(self.recorder.path),
            "plan": self.plan.name,
            "uri": self.uri,
            "duration_s": round(end, 3),
            "aborted": bool(journal.causes),
            "cause": journal.causes[0] if journal.causes else "",
        }

    def summary(self) -> dict[str, Any]:
        """:meth:`outcome`, then packets per block, setpoint count and period jitter."""
        journal, telemetry = self.journal, self.telemetry
        end = self.t_close if math.isfinite(self.t_close) else journal.now()
        blocks = {name: block_summary(fw_ms=telemetry.fw_ms[name], period_s=p,
                                      silence_s=end - telemetry.last_block.get(name, end))
                  for name, p in self.block_periods.items()}
        return {
            **self.outcome(),
            **({"excitation_cut": self.cut} if self.cut else {}),
            "blocks": blocks,
            "setpoints": setpoint_summary(sent_t=self.out.sent_t, period_s=self.schedule.period,
                                          scheduled=self.n_scheduled,
                                          planned=len(self.schedule),
                                          stopped=self.out.stopped,
                                          after_stop=self.out.fed),
        }


def fly_plan(*, plan: Plan | str | Path, out: str | Path, uri: str = DEFAULT_URI,
             listeners: Sequence[FlightListener] = (), limits: RateLimits | None = None,
             connect_timeout_s: float = 10.0,
             tick_hook: Callable[[int], None] | None = None, tag: str = "",
             reraise: bool = True, arm: bool = False) -> FlightResult:
    """Fly ``plan`` (a :class:`Plan`, a path or a shipped plan's name) over ``uri``, record the
    session into folder ``out`` and return the :class:`FlightResult`.

    ``tick_hook(k)`` runs before setpoint ``k`` is sent (an exception in it is a runner error:
    the flight aborts safely). Raises :class:`~groundstation.errors.LinkError` when the Crazyflie
    cannot be reached or lacks a logged variable (nothing is flown then). ``tag`` (e.g.
    ``validation``) goes into the file name, ``PLAN-TAG-STAMP.h5``, and the ``tag`` metadata.

    A ``SystemExit`` or ``KeyboardInterrupt`` a listener raised ends the flight (its landing
    flown, the file closed) and is then raised from here; with ``reraise=False`` it is
    returned instead, as :attr:`FlightResult.escaped`, so the caller can report the flight
    first (``groundstation fly`` prints the summary, then exits as for any aborted flight).

    A vehicle that does not arm itself (a Crazyflie Brushless) is refused before take-off
    unless ``arm``: then it is asked to arm (``fly --arm``); on a firmware that logs no
    ``supervisor.info`` the request is sent unconfirmed, with a warning, and the flight goes on.
    """
    check_uri(uri)
    plan = plan if isinstance(plan, Plan) else load_plan(plan)
    schedule = plan.compile()
    if limits is None:  # the plan's [safety] max_rate_deg_s, else the default
        rate = schedule.safety.max_rate_deg_s
        limits = RateLimits() if rate is None else RateLimits(max_rate_deg_s=rate)
    # The folder and the file name are checked before connecting; the name is claimed when the
    # file is created (Recorder.begin), so two flights into one folder never collide.
    recorder = Recorder(session_path(out=out, plan_name=plan.name, tag=tag), unique=True)
    runner = _Runner(plan=plan, schedule=schedule, uri=uri, recorder=recorder,
                     listeners=listeners, limits=limits or RateLimits(),
                     connect_timeout_s=connect_timeout_s, tick_hook=tick_hook, tag=tag,
                     reraise=reraise, arm=arm)
    with signal_handlers(runner.request_abort), prompt_thread_switches():
        return runner.run()
