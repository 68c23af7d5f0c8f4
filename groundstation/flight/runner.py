"""The flight runner: stream a plan's setpoints on a drift-free schedule, record, stay safe.

:func:`fly_plan` connects (:mod:`groundstation.flight.link`), checks the TOC and the battery,
records the flight through :class:`~groundstation.recorder.Recorder` and any other
:class:`FlightListener`, and returns a :class:`FlightResult` (session path, summary, abort cause).

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

**Safety.** SIGINT/SIGTERM (handlers installed while flying, restored after), link loss (cflib's, or
no log packet for :data:`LINK_SILENCE_S` = 0.5 s of flight time while flying), an
exception in the runner, a measured rate beyond :class:`RateLimits`, a setpoint that is not
finite (NaN or inf is never sent) or a battery below ``vehicle.min_vbat`` at take-off each
record an event (source ``safety``) and end with the stop setpoint; if the plan's
``on_abort`` is ``descend`` and the link is up, the
:meth:`~groundstation.plan.schedule.Schedule.abort_schedule` descent streams first at the same rate,
so there is never more than one period without a setpoint (never after a link loss: no
telemetry, no descent). The stop setpoint is delivered before the link closes on every path,
the abort path failing included (:meth:`~groundstation.flight.link.Link.deliver_stop`), and
recorded as a row and an event. The summary counts the log packets missing up to the moment the link
closed, so a link dead before the end shows as dropped packets. A listener that raises is dropped
(with an event); the flight goes on. Without its recorder the flight aborts; a session file
that cannot be created (folder, name) is a one-line error before take-off, nothing flown.

**Sources.** A listener with ``streams()``, ``poll()``, ``finish(path=)``
(:mod:`groundstation.flight.listeners`; live identification, :mod:`groundstation.flight.liveid`)
adds streams, polled after each setpoint (rows to the recorder only; a request to end the
excitation: the plan goes on after its last excitation phase, no period skipped), and is
finished after the stop; its entries join the summary.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from cfsession.writer import event_rows, standard_streams
from groundstation.errors import FlightAborted, GroundStationError, SessionError
from groundstation.flight.clock import clock_for_uri
from groundstation.flight.link import (
    ATTITUDE_BLOCK,
    BATTERY_BLOCK,
    BLOCK_PERIOD_S,
    DEFAULT_URI,
    FLIGHT_BLOCKS,
    check_uri,
    install_drivers,
    open_link,
)
from groundstation.flight.listeners import FlightListener, Listeners
from groundstation.flight.params import (
    ParamChange,
    check_parameters,
    restore_after_flight,
    set_for_flight,
)
from groundstation.flight.realtime import prompt_thread_switches, signal_handlers
from groundstation.flight.result import FlightResult, block_summary, setpoint_summary
from groundstation.flight.safety import RateLimits
from groundstation.plan import Plan, Schedule, load_plan
from groundstation.plan.altitude import AltitudeHold
from groundstation.recorder import Recorder, session_path

__all__ = ["FlightListener", "FlightResult", "RateLimits", "altitude_block_period",
           "block_summary", "fly_plan"]

log = logging.getLogger(__name__)

ALTITUDE_BLOCK = "altitude"
"""Log block of the plan's ``[altitude_hold]`` variable (only when the plan has one)."""
LINK_SILENCE_S = 0.5
"""No log packet for this long (flight clock) while flying is link loss: the flight aborts.
The three 50 Hz blocks make it 75 missing packets; the Crazyflie's own watchdog levels out
after 0.5 s without a setpoint too."""
_SILENCE_GRACE_S = 0.1  # wall s: cflib's threads get this long to deliver what has arrived


def altitude_block_period(setpoint_period_s: float) -> float:
    """The altitude block's period: twice the setpoint rate, at least 10 ms."""
    return max(0.01, round(setpoint_period_s / 2, 2))


class _Runner:
    """One flight; see the module docstring. Use :func:`fly_plan`."""

    def __init__(self, *, plan: Plan, schedule: Schedule, uri: str, recorder: Recorder,
                 listeners: Sequence[FlightListener], limits: RateLimits,
                 connect_timeout_s: float, tick_hook: Callable[[int], None] | None,
                 tag: str = "") -> None:
        self.plan, self.schedule, self.uri, self.tag = plan, schedule, uri, tag
        self.recorder, self.limits, self.tick_hook = recorder, limits, tick_hook
        self.listeners = Listeners(recorder=recorder, others=listeners,
                                   on_error=self._listener_failed)
        self.end_excitation, self.cut = "", {}  # a source's request; what was skipped
        self.connect_timeout_s = connect_timeout_s
        # the only hand-off from cflib's threads: log rows, link events, aborts
        self.inbox: queue.SimpleQueue[tuple] = queue.SimpleQueue()
        self.cancel = threading.Event()  # set by request_abort: also cancels a connect
        install_drivers()  # a link driver may bring its own clock (sim://): register it first
        self.clock = clock_for_uri(uri)
        self.origin = self.clock.now()
        self.start_ns = time.time_ns()
        self.pending: dict[str, list[tuple]] = defaultdict(list)
        self.fw_ms: dict[str, list[int]] = defaultdict(list)  # firmware ms per log block
        self.delivered: dict[str, int] = defaultdict(int)
        self.sent_t: list[float] = []
        self.n_scheduled = 0
        self.causes: list[str] = []
        self.flying = False
        self.vbat: float | None = None
        self.over_limit_runs = [0, 0, 0]  # consecutive packets beyond the rate limit, per axis
        self.console = ""
        self.link: Any = None
        self.t_first = math.nan
        self.last_log = -math.inf  # flight time of the newest log packet (any block)
        self.last_block: dict[str, float] = {}  # ... of each block
        self.t_close = math.nan  # flight time the link was closed (log packets end there)
        self.silent = False  # link loss found by the runner's silence watch
        self.stopped = False  # the stop setpoint has been delivered
        self.block_periods: dict[str, float] = {}
        cfg = schedule.altitude_hold
        self.hold = AltitudeHold(cfg, period_s=schedule.period) if cfg else None
        self.extra_blocks = {ALTITUDE_BLOCK: (cfg.variable,)} if cfg else {}
        self.slow_blocks = {name: (variables, period)
                            for name, variables, period in (BATTERY_BLOCK, ATTITUDE_BLOCK)}
        self.altitude_m: float | None = None  # last logged altitude for the altitude hold
        self.params: list[ParamChange] = []  # the plan's [parameters], once written

    # ------------------------------------------------------------------ helpers
    def now(self) -> float:
        return self.clock.now() - self.origin

    def event(self, text: str, *, level: str = "info", source: str = "runner") -> None:
        log.log(logging.ERROR if level == "error" else logging.INFO, "%s: %s", source, text)
        self.pending["events"].extend(event_rows(t=self.now(), text=text, level=level,
                                                 source=source))

    def request_abort(self, cause: str) -> None:
        """Thread- and signal-safe: the runner aborts at its next deadline (or stops
        connecting at once)."""
        self.cancel.set()
        self.inbox.put(("abort", self.clock.now(), cause))

    def _cause(self, text: str, *, level: str = "error") -> None:
        self.causes.append(text)
        self.event(text if len(self.causes) == 1 else f"during the abort: {text}",
                   level=level, source="safety")

    def _deadline(self, k: int) -> float:
        return self.t_first + k * self.schedule.period

    # ------------------------------------------------------------------ queue and listeners
    def collect(self) -> None:
        """Drain the queue into pending rows; check link, signals and limits (no I/O)."""
        while True:
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                return
            kind, t = item[0], item[2] if item[0] == "log" else item[1]
            t -= self.origin
            if kind == "log":
                _, block, _, fw_ms, values = item
                self.pending[block].append((t, fw_ms, *values))
                self.last_log = self.last_block[block] = t
                self.fw_ms[block].append(fw_ms)
                self.delivered[block] += 1
                if block == BATTERY_BLOCK[0]:
                    self.vbat = float(values[0])
                elif block == ALTITUDE_BLOCK:
                    self.altitude_m = float(values[0])
                elif block == "gyro" and self.flying:
                    self._check_rates(values)
            elif kind == "console":
                self.console += item[2]
                *lines, self.console = self.console.split("\n")
                for line in lines:
                    self.event(line.rstrip(), source="console")
            elif kind == "link":
                self.pending["link"].append((t, item[2], item[3]))
            elif kind == "lost":
                self._cause(f"link lost: {item[2]}")
            elif kind == "abort":
                self._cause(item[2], level="warning")
            else:
                self.event(str(item[2]), level="warning", source="link")

    def _check_rates(self, values: Sequence[float]) -> None:
        lim = self.limits
        for i, v in enumerate(values):
            runs = self.over_limit_runs
            runs[i] = runs[i] + 1 if abs(v) > lim.max_rate_deg_s else 0
            if runs[i] == lim.samples and not self.causes:
                self._cause(f"limit: gyro.{'xyz'[i]} = {v:.0f} deg/s beyond "
                            f"{lim.max_rate_deg_s:g} deg/s for {lim.samples} samples")

    def _listener_failed(self, what: str, recorder: bool) -> None:
        if recorder:
            self._cause(f"recording failed: {what}")
        else:
            self.event(f"{what}; listener dropped, flight continues", level="error")

    def dispatch(self) -> None:
        """The sources polled, then every pending row (events of a failed poll included)."""
        reason = self.listeners.poll()  # always polled: the sources' rows are recorded
        self.end_excitation = self.end_excitation or reason
        pending, self.pending = self.pending, defaultdict(list)
        self.listeners.deliver(pending)

    # ------------------------------------------------------------------ commander
    def send(self, sp: tuple[float, float, float, int], *, phase_id: int, tick: int) -> None:
        roll, pitch, yaw_rate, thrust = sp
        self.link.send_setpoint(roll=roll, pitch=pitch, yaw_rate=yaw_rate, thrust=thrust)
        t = self.now()
        self.sent_t.append(t)
        self.pending["setpoints"].append((t, roll, pitch, yaw_rate, thrust, phase_id, tick))

    def stop(self, why: str) -> None:
        """The stop setpoint, delivered (:meth:`Link.deliver_stop`: repeated, the driver's
        send queue drained) and recorded as a thrust-0 row with tick -1 and an event."""
        t = self.now()
        self.flying = False
        self.link.deliver_stop()
        self.stopped = True
        self.pending["setpoints"].append((t, 0.0, 0.0, 0.0, 0, -1, -1))
        self.event(f"stop setpoint sent ({why})", source="safety" if self.causes else "runner")

    def last_stop(self) -> None:
        """On the way out of :meth:`run` when no stop has been delivered yet (the abort path
        failed): the stop, recorded; if even that fails, the bare stop setpoint."""
        try:
            self.stop(f"last resort: {self.causes[0] if self.causes else 'runner exit'}")
        except Exception as exc:
            log.exception("stop setpoint failed")
            self.event(f"stop setpoint failed ({type(exc).__name__}: {exc}); sending it bare",
                       level="error", source="safety")
            try:
                self.link.send_stop()
            except Exception:
                log.exception("bare stop setpoint failed")

    def phase(self, *, phase_id: int, name: str, kind: str, planned_s: float) -> None:
        self.pending["phases"].append((self.now(), phase_id, name.encode()[:32],
                                       kind.encode()[:16]))
        self.event(f"phase {name} ({kind}) starts, {planned_s:g} s planned")

    def wait(self, t: float) -> None:
        self.clock.sleep_until(t)
        self.collect()
        if self.flying and not self.causes and self.now() - self.last_log > LINK_SILENCE_S:
            self._check_silence()

    def _check_silence(self) -> None:
        """No log packet for :data:`LINK_SILENCE_S` of flight time: give cflib's threads
        :data:`_SILENCE_GRACE_S` of wall time to deliver what has already arrived (a host
        too busy to run them is not a dead link), then call it link loss."""
        give_up = time.monotonic() + _SILENCE_GRACE_S
        while time.monotonic() < give_up:
            time.sleep(0.01)
            self.collect()
            if self.now() - self.last_log <= LINK_SILENCE_S or self.causes:
                return
        self.silent = True
        self._cause(f"link lost: no log packet for {self.now() - self.last_log:.2f} s "
                    f"(limit {LINK_SILENCE_S:g} s)")

    # ------------------------------------------------------------------ the flight
    def preflight(self) -> bool:
        """Wait for every log block and a battery reading; refuse a low battery."""
        names = [*FLIGHT_BLOCKS, *self.slow_blocks, *self.extra_blocks]
        give_up = time.monotonic() + max(3.0, self.connect_timeout_s / 2)
        t = self.clock.now()
        while not self.causes:
            missing = [n for n in names if not self.delivered[n]]
            if not missing and (self.vbat is not None or BATTERY_BLOCK[0] not in names):
                break
            if time.monotonic() > give_up:
                self._cause(f"log blocks {missing} delivered nothing; check the link")
                return False
            t += self.schedule.period
            self.wait(t)
            self.dispatch()
        if self.causes:
            return False
        v = self.schedule.vehicle
        if self.vbat is not None and self.vbat < v.min_vbat:
            self._cause(f"battery {self.vbat:.2f} V below vehicle.min_vbat = {v.min_vbat:g} V: "
                        "refusing to take off; charge or swap the battery")
            return False
        battery = "no battery reading" if self.vbat is None else f"battery {self.vbat:.2f} V"
        self.event(f"preflight ok: {battery}, log blocks {names} running")
        return True

    def fly(self) -> int:
        """Unlock, then every scheduled setpoint; returns the next unsent tick."""
        s, k = self.schedule, 0
        self.t_first = self.clock.now() + s.period
        self.send((0.0, 0.0, 0.0, 0), phase_id=-1, tick=-1)  # releases the thrust lock
        self.flying = True
        self.last_log = max(self.last_log, self.now())  # the silence watch starts here
        current = -1
        while k < len(s) and not self.causes:
            self.wait(self._deadline(k))
            if self.causes:
                break
            if self.tick_hook is not None:
                self.tick_hook(k)
            ph = s.phase_at(k)
            if self.end_excitation and ph.kind == "excitation" and not self.cut:
                end = max(p.end_tick for p in s.phases if p.kind == "excitation")
                self.t_first -= (end - k) * s.period  # setpoint `end` goes out now
                self.cut = {"at_s": round(self.now(), 3), "reason": self.end_excitation,
                            "skipped_s": round((end - k) * s.period, 3)}
                self.event(f"excitation ended {self.cut['skipped_s']:.1f} s early: "
                           f"{self.end_excitation}")
                k, ph = end, s.phase_at(end)
            if ph.id != current:
                current = ph.id
                self.phase(phase_id=ph.id, name=ph.name, kind=ph.kind, planned_s=ph.duration)
            sp = self._trimmed(s.setpoint(k), kind=ph.kind)
            if not _finite(sp):
                self._cause(f"setpoint {k} (phase {ph.name}) is not finite "
                            f"({', '.join(f'{v:g}' for v in sp)}); not sent")
                break
            self.send(sp, phase_id=ph.id, tick=k)
            self.n_scheduled += 1
            k += 1
            self.dispatch()
        return k

    def _trimmed(self, sp: tuple[float, float, float, int], *, kind: str
                 ) -> tuple[float, float, float, int]:
        """The setpoint with the altitude-hold trim added to its thrust (within the limits)."""
        if self.hold is None:
            return sp
        active = kind in self.hold.config.kinds
        if active and self.altitude_m is None:
            self._cause(f"altitude hold: no {self.hold.config.variable} sample yet")
        trim = self.hold.update(z=self.altitude_m, active=active)
        if not trim:
            return sp
        v = self.schedule.vehicle
        roll, pitch, yaw_rate, thrust = sp
        return roll, pitch, yaw_rate, min(max(thrust + trim, v.thrust_min), v.thrust_max)

    def abort(self, k: int) -> None:
        """After a cause: the plan's descent if the link is up, then the stop setpoint."""
        lost = self.link is None or self.link.lost or self.silent
        n_causes = len(self.causes)
        descent = self.schedule.abort_schedule(k) if self.flying and not lost else None
        if descent is not None and len(descent):
            self.phase(phase_id=-1, name="abort", kind="abort", planned_s=descent.duration)
            for j in range(len(descent)):
                self.wait(self._deadline(k + j))
                if len(self.causes) > n_causes or self.link.lost or self.silent:
                    break
                sp = descent.setpoint(j)
                if not _finite(sp):
                    self._cause(f"descent setpoint {j} is not finite; stopping at once")
                    break
                self.send(sp, phase_id=-1, tick=-1)
                self.dispatch()
            else:
                self.wait(self._deadline(k + len(descent)))
        if self.link is not None:
            if self.link.lost or self.silent:
                self.event("no link: the Crazyflie's watchdog levels out after 0.5 s and stops "
                           "the motors after 2 s", level="warning", source="safety")
            self.stop(f"abort: {self.causes[0]}")

    def run(self) -> FlightResult:
        link = self.link = open_link(uri=self.uri, clock=self.clock, post=self.inbox.put,
                                     timeout_s=self.connect_timeout_s, cancel=self.cancel)
        k, begun = 0, False
        try:
            blocks = link.plan_blocks(blocks=FLIGHT_BLOCKS, period_s=BLOCK_PERIOD_S)
            if link.toc_type(BATTERY_BLOCK[1][0]) is None:  # e.g. CrazySim's unpatched SITL
                del self.slow_blocks[BATTERY_BLOCK[0]]
                self.event(f"no {BATTERY_BLOCK[1][0]} in the log TOC (no power management, "
                           "e.g. an unpatched SITL build): battery check skipped",
                           level="warning")
            for name, (variables, period) in self.slow_blocks.items():
                blocks += link.plan_blocks(blocks={name: variables}, period_s=period)
            if self.extra_blocks:  # altitude for the hold, at twice the setpoint rate
                period = altitude_block_period(self.schedule.period)
                blocks += link.plan_blocks(blocks=self.extra_blocks, period_s=period)
            self.block_periods = {b.name: b.period_s for b in blocks}
            changes = check_parameters(link.cf, self.plan.parameters)  # before any file
            meta = {**link.metadata(), **self._plan_metadata(),
                    **({"plan_parameters": {c.name: {"value": c.value, "was": c.old}
                                            for c in changes}} if changes else {})}
            streams = [*(b.spec() for b in blocks), *standard_streams()]
            own = [spec for specs in self.listeners.from_sources("streams") for spec in specs]
            try:  # the file first: a flight that cannot be recorded is not flown
                self.recorder.begin(streams=[*streams, *own], metadata=meta)
            except (GroundStationError, SessionError) as exc:
                raise SessionError(f"{exc}; nothing flown") from None
            except Exception as exc:
                log.debug("recorder.begin failed", exc_info=True)
                raise FlightAborted(f"cannot record to {self.recorder.path} "
                                    f"({type(exc).__name__}: {exc}); nothing flown") from None
            begun = True
            self.listeners.begin(streams=streams, metadata=meta)
            link.start_blocks(blocks)
            try:
                if self.write_params(changes) and self.preflight():
                    k = self.fly()
            except Exception as exc:
                log.exception("flight runner error")
                self._cause(f"runner error: {type(exc).__name__}: {exc}")
            try:
                if self.causes:
                    self.abort(k)
                else:
                    self.wait(self._deadline(k))
                    self.stop("landed")
                    self.event("flight complete")
                self._tail()
            except Exception as exc:  # the stop follows in the finally clause
                log.exception("abort path failed")
                self._cause(f"runner error while stopping: {type(exc).__name__}: {exc}")
        finally:
            if begun and not self.stopped:  # every path out ends with the stop
                self.last_stop()
            if self.params:
                restore_after_flight(self.link.cf, self.params, event=self.event,
                                     link_up=not (self.link.lost or self.silent or
                                                  self.link.stuck))
            self.t_close = self.now()
            link.close()
            self.collect()
            finished = (self.listeners.from_sources("finish", path=self.recorder.path)
                        if begun else [])
            summary = self.summary()
            for entries in finished:
                summary.update(entries)
            if begun:
                self.dispatch()
                self.listeners.end(summary=summary)
        return FlightResult(path=self.recorder.path, summary=summary,
                            cause=self.causes[0] if self.causes else "")

    def write_params(self, changes: list[ParamChange]) -> bool:
        """The plan's ``[parameters]`` written (:func:`~.params.set_for_flight`); False after a
        cause (nothing is flown then). Restored after the stop, even if only some were
        written."""
        self.params = changes
        failed = set_for_flight(self.link.cf, changes, event=self.event)
        if failed:
            self._cause(failed)
        return not failed

    def _tail(self, seconds: float = 0.5) -> None:
        """Keep recording a moment after the stop so the file shows the motors at rest."""
        if self.link.lost or self.silent:
            return
        t = self.clock.now()
        for _ in range(round(seconds / self.schedule.period)):
            t += self.schedule.period
            self.wait(t)
            self.dispatch()

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

    def summary(self) -> dict[str, Any]:
        """Duration, packets per block, setpoint count and period jitter, cause, file."""
        end = self.t_close if math.isfinite(self.t_close) else self.now()
        blocks = {name: block_summary(fw_ms=self.fw_ms[name], period_s=p,
                                      silence_s=end - self.last_block.get(name, end))
                  for name, p in self.block_periods.items()}
        return {
            "file": str(self.recorder.path),
            "plan": self.plan.name,
            "uri": self.uri,
            "duration_s": round(end, 3),
            "aborted": bool(self.causes),
            "cause": self.causes[0] if self.causes else "",
            **({"excitation_cut": self.cut} if self.cut else {}),
            "blocks": blocks,
            "setpoints": setpoint_summary(sent_t=self.sent_t, period_s=self.schedule.period,
                                          scheduled=self.n_scheduled,
                                          planned=len(self.schedule)),
        }


def _finite(sp: Sequence[float]) -> bool:
    """Whether every value of a setpoint is a finite number (never send NaN or inf)."""
    return all(math.isfinite(v) for v in sp)


def fly_plan(*, plan: Plan | str | Path, out: str | Path, uri: str = DEFAULT_URI,
             listeners: Sequence[FlightListener] = (), limits: RateLimits | None = None,
             connect_timeout_s: float = 10.0,
             tick_hook: Callable[[int], None] | None = None, tag: str = "") -> FlightResult:
    """Fly ``plan`` (a :class:`Plan`, a path or a shipped plan's name) over ``uri``, record the
    session into folder ``out`` and return the :class:`FlightResult`.

    ``tick_hook(k)`` runs before setpoint ``k`` is sent (an exception in it is a runner error:
    the flight aborts safely). Raises :class:`~groundstation.errors.LinkError` when the Crazyflie
    cannot be reached or lacks a logged variable (nothing is flown then). ``tag`` (e.g.
    ``validation``) goes into the file name, ``PLAN-TAG-STAMP.h5``, and the ``tag`` metadata.
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
                     connect_timeout_s=connect_timeout_s, tick_hook=tick_hook, tag=tag)
    with signal_handlers(runner.request_abort), prompt_thread_switches():
        return runner.run()
