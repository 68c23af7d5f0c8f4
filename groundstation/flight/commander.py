"""The setpoints a flight sends, each recorded as sent, and every way out of a flight: landing,
the abort descent, the stop setpoint, the last resort.

**Schedule.** Setpoint :math:`k` is due at :math:`t_k = t_0 + k / f_s` on the flight clock
(:meth:`Commander.deadline`), never :math:`t_{k-1} + 1/f_s`, so lateness never accumulates.
Every setpoint sent is a row of the ``setpoints`` stream (thrust as sent) and a send time for
the jitter summary; a setpoint that is not finite (NaN or inf) is never sent.

**Stop.** The stop setpoint is delivered (:meth:`~groundstation.flight.link.Link.deliver_stop`:
repeated, the driver's send queue drained) and recorded as a thrust-0 row with tick -1 and an
event, on every path: one period after the last setpoint (:meth:`Commander.land`), after an
abort (:meth:`Commander.abort`: if the plan's ``on_abort`` is ``descend`` and the link is up,
the :meth:`~groundstation.plan.schedule.Schedule.abort_schedule` descent streams first at the
same rate, so there is never more than one period without a setpoint; never after a link loss:
no telemetry, no descent), and when even that path failed (:meth:`Commander.last_stop`, the
bare stop setpoint if recording it fails too).

**After the stop** (:meth:`Commander.tail`). The firmware's supervisor counts the vehicle as
flying until 2 s after a motor last ran above idle (``IS_FLYING_HYSTERESIS_THRESHOLD``); a
commander silent for 0.5 s in that time sends it to level-out and, at 2 s, to *Locked*, which
only a restart ends (``supervisor_state_machine.c``: level-out has no way to *Landed*). So a
flight that ran its motors keeps sending the stop setpoint, one per setpoint period and each
recorded (thrust 0, tick -1), until ``supervisor.info`` reports it landed (bit 4 clear;
:data:`LANDED_WITHIN_S` at most; without ``supervisor.info`` in the log, :data:`FEED_BLIND_S`).
A locked vehicle (bit 6; its flying bit is clear too) is reported locked, a crashed one (bit
7) crashed, never landed. After a link loss found by the silence watch alone (no log packet,
cflib's link still up: the stop setpoints may still reach the vehicle) the stop is fed blind
for :data:`FEED_BLIND_S`. No stop request (Ctrl-C, a hangup) ends the feed; cflib's link loss,
a failed send and :data:`LANDED_WITHIN_S` do.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

from groundstation.flight.blocks import CRASHED_BIT, FLYING_BIT, LOCKED_BIT
from groundstation.flight.journal import Journal
from groundstation.flight.telemetry import Telemetry
from groundstation.plan import Schedule

__all__ = ["FEED_BLIND_S", "LANDED_WITHIN_S", "SETPOINT_LATE_S", "Commander", "finite"]

log = logging.getLogger("groundstation.flight.runner")  # the runner's way out: logged as its

#: A setpoint due longer ago than this (flight clock) ends the flight: the firmware's watchdog
#: (``supervisor.c``) has levelled the vehicle out by then, so it no longer flies the plan. In
#: the abort's descent the rest of it is re-timed from then instead (never a burst).
SETPOINT_LATE_S = 0.5
#: After the stop, the stop setpoint is fed at most this long (flight clock) for the supervisor
#: to report the vehicle landed: its 2 s is-flying hysteresis, two periods of the battery block
#: that logs ``supervisor.info`` (0.5 s), and a margin.
LANDED_WITHIN_S = 4.0
#: Without ``supervisor.info`` in the log: the stop setpoint is fed this long (the hysteresis
#: and a margin).
FEED_BLIND_S = 2.5

Setpoint = tuple[float, float, float, int]  # roll deg, pitch deg, yaw rate deg/s, thrust PWM


def finite(sp: Sequence[float]) -> bool:
    """Whether every value of a setpoint is a finite number (never send NaN or inf)."""
    return all(math.isfinite(v) for v in sp)


class Commander:
    """Setpoints out over ``link`` on the schedule's grid, recorded in ``journal``."""

    def __init__(self, *, link: Any, journal: Journal, telemetry: Telemetry,
                 schedule: Schedule) -> None:
        self.link, self.journal, self.telemetry, self.schedule = (link, journal, telemetry,
                                                                  schedule)
        self.t_first = math.nan  # flight clock time setpoint 0 is due
        self.sent_t: list[float] = []
        self.stopped = False  # the stop setpoint has been delivered
        self.motors_ran = False  # a setpoint with thrust went out: the supervisor may count
        self.fed: dict[str, Any] = {}  # the stop setpoints fed after it (:meth:`tail`)

    @property
    def link_down(self) -> bool:
        """The link was lost (cflib's report, a stuck call, or the silence watch)."""
        return self.link.lost or self.telemetry.silent

    def deadline(self, k: int) -> float:
        return self.t_first + k * self.schedule.period

    def lateness(self, k: int) -> float:
        """Seconds since setpoint ``k`` was due (negative: not yet)."""
        return self.journal.clock.now() - self.deadline(k)

    def send(self, sp: Setpoint, *, phase_id: int, tick: int) -> None:
        roll, pitch, yaw_rate, thrust = sp
        self.link.send_setpoint(roll=roll, pitch=pitch, yaw_rate=yaw_rate, thrust=thrust)
        t = self.journal.now()
        self.sent_t.append(t)
        self.motors_ran = self.motors_ran or thrust > 0
        self.journal.pending["setpoints"].append((t, roll, pitch, yaw_rate, thrust, phase_id,
                                                  tick))

    def stop(self, why: str) -> None:
        """The stop setpoint, delivered (:meth:`Link.deliver_stop`: repeated, the driver's
        send queue drained) and recorded as a thrust-0 row with tick -1 and an event."""
        journal = self.journal
        t = journal.now()
        self.telemetry.flying = False
        self.link.deliver_stop()
        self.stopped = True
        self.telemetry.stop_t = min(self.telemetry.stop_t, t)  # the first one's time
        journal.pending["setpoints"].append((t, 0.0, 0.0, 0.0, 0, -1, -1))
        journal.event(f"stop setpoint sent ({why})",
                      source="safety" if journal.causes else "runner")

    def last_stop(self) -> None:
        """On the way out of a flight when no stop has been delivered yet (the abort path
        failed): the stop, recorded; if even that fails, the bare stop setpoint."""
        causes = self.journal.causes
        try:
            self.stop(f"last resort: {causes[0] if causes else 'runner exit'}")
        except Exception as exc:
            log.exception("stop setpoint failed")
            self.journal.event(f"stop setpoint failed ({type(exc).__name__}: {exc}); sending "
                               "it bare", level="error", source="safety")
            try:
                self.link.send_stop()
            except Exception:
                log.exception("bare stop setpoint failed")

    def land(self, k: int) -> None:
        """The end of a plan flown through: the stop one period after setpoint ``k - 1``."""
        self.telemetry.wait(self.deadline(k))
        self.stop("landed")
        self.journal.landed = not (self.link_down or getattr(self.link, "stuck", False))
        self.journal.event("flight complete")

    def abort(self, k: int) -> None:
        """After a cause: the plan's descent if the link is up, then the stop setpoint."""
        journal, telemetry = self.journal, self.telemetry
        n_causes = len(journal.causes)
        # a late abort (the host held up) descends from now: never a burst of past-due setpoints
        self.t_first += max(self.lateness(k), 0.0)
        descent = (self.schedule.abort_schedule(k) if telemetry.flying and not self.link_down
                   else None)
        if descent is not None and len(descent):
            journal.phase(phase_id=-1, name="abort", kind="abort", planned_s=descent.duration)
            for j in range(len(descent)):
                telemetry.wait(self.deadline(k + j))
                if len(journal.causes) > n_causes or self.link_down:
                    break
                late = self.lateness(k + j)
                if late > SETPOINT_LATE_S:  # held up mid-descent: the rest from now, no burst
                    self.t_first += late
                    journal.event(f"descent setpoint {j} {late:.2f} s late: the rest of the "
                                  "descent from now", level="warning", source="safety")
                sp = descent.setpoint(j)
                if not finite(sp):
                    journal.cause(f"descent setpoint {j} is not finite; stopping at once")
                    break
                self.send(sp, phase_id=-1, tick=-1)
                journal.dispatch()
            else:
                telemetry.wait(self.deadline(k + len(descent)))
        if self.link_down:
            journal.event("no link: the Crazyflie's watchdog levels out after 0.5 s and stops "
                          "the motors after 2 s", level="warning", source="safety")
        self.stop(f"abort: {journal.causes[0]}")

    def tail(self, seconds: float = 0.5) -> None:
        """Keep recording at least ``seconds`` after the stop so the file shows the motors at
        rest; after a flight that ran its motors, keep the stop setpoint fed until the vehicle
        reports landed (module docstring). A stop request does not end the feed (it only sends
        motors-off, 4 s at most, and ending it early costs a restart); a lost link or a failed
        send does. ``fed`` says how it ended and an event says what it means."""
        if self._link_gone():
            return
        journal, telemetry, period = self.journal, self.telemetry, self.schedule.period
        feed = self.motors_ran
        blind = telemetry.silent  # no telemetry, but cflib's link is up: the stops may arrive
        now = journal.clock.now()  # on the setpoint grid from the stop, never a burst
        stop_t = telemetry.stop_t
        t = stop_t + journal.origin if math.isfinite(stop_t) else now
        t += max(math.floor((now - t) / period) - 1, 0) * period  # one overdue at most
        t0, n, why = t, 0, ""
        while True:
            t += period
            telemetry.wait(t)
            journal.dispatch()
            elapsed = t - t0
            if feed:
                why = self._feed_ends(blind=blind, elapsed=elapsed)
                feed = not why
            if elapsed >= seconds - 1e-9 and not feed:
                break
            if feed:
                try:
                    self.link.send_stop()
                except Exception as exc:  # the stop was delivered; this only keeps it fed
                    log.warning("stop setpoint not fed", exc_info=True)
                    why, feed = f"send failed: {type(exc).__name__}: {exc}", False
                    continue
                n += 1
                journal.pending["setpoints"].append((journal.now(), 0.0, 0.0, 0.0, 0, -1, -1))
        if self.motors_ran:
            self._fed(n=n, why=why, seconds=round(n * period, 3))

    def _feed_ends(self, *, blind: bool, elapsed: float) -> str:
        """Why the feed ends now, ``elapsed`` seconds after the stop: what ``supervisor.info``
        says (:meth:`_supervisor_says`), the link gone, its blind time or its limit over;
        ``""``: it goes on."""
        said = None if blind else self._supervisor_says()
        if said:
            return said
        if self._link_gone():
            return "link lost"
        if said is None and elapsed >= FEED_BLIND_S:
            return "no telemetry" if blind else "no supervisor.info"
        return "timeout" if elapsed >= LANDED_WITHIN_S else ""

    def _link_gone(self) -> bool:
        """cflib lost the link, or one of its calls never returned: nothing more is sent."""
        return bool(self.link.lost or getattr(self.link, "stuck", False))

    def _supervisor_says(self) -> str | None:
        """What ``supervisor.info`` logged after the stop says: ``"landed"`` (bit 4 clear),
        ``"locked"`` (bit 6: its supervisor stopped it for good; the flying bit is clear then
        too), ``"crashed"`` (bit 7: it tumbled in flight), ``""`` while it still flies or until
        a value sent after the stop arrives; None if the log has no ``supervisor.info``."""
        info = self.telemetry.supervisor
        if info is None:
            return None
        if not self.telemetry.supervisor_t > self.telemetry.stop_t:
            return ""
        if info & LOCKED_BIT:
            return "locked"
        if info & CRASHED_BIT:  # tumbled in flight: stopped, no lock to keep it from
            return "crashed"
        return "" if info & FLYING_BIT else "landed"

    def _fed(self, *, n: int, why: str, seconds: float) -> None:
        self.fed = {"setpoints": n, "seconds": seconds, "ended": why}
        fed = f"the stop setpoint fed {n} more times ({seconds:g} s)"
        if why == "landed":
            self.journal.event(f"the Crazyflie reports landed; {fed}")
        elif why == "no supervisor.info":
            self.journal.event(f"{fed}, the supervisor's 2 s is-flying time and a margin (no "
                               "supervisor.info in the log to see it land)")
        elif why == "locked":
            self.journal.event(f"{fed}; the Crazyflie reports locked (supervisor.info "
                               f"0x{self.telemetry.supervisor:04x}): its supervisor stopped it "
                               "(a commander watchdog timeout, an emergency stop or a crash); "
                               "only a restart unlocks it", level="warning", source="safety")
        elif why == "crashed":
            self.journal.event(f"{fed}; the Crazyflie reports crashed (supervisor.info "
                               f"0x{self.telemetry.supervisor:04x}): it tumbled in flight and "
                               "its motors are stopped; set it upright, then a crash recovery "
                               "(cfclient) or a restart", level="warning", source="safety")
        elif why == "no telemetry":
            self.journal.event(f"{fed} without telemetry (the link went silent), the "
                               "supervisor's 2 s is-flying time and a margin: if they did not "
                               "reach it, its supervisor may have locked it (the next preflight "
                               "says so)", level="warning", source="safety")
        else:
            self.journal.event(f"{fed}; {why} before the Crazyflie reported landed: its "
                               "supervisor may have locked it (a restart unlocks it; the next "
                               "preflight says so)", level="warning", source="safety")
