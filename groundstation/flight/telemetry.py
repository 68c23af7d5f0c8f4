"""What comes back from the Crazyflie during a flight, taken in on the runner's thread and
watched: log packets, console text, link statistics, link loss, abort requests.

cflib's callbacks only put tuples on :attr:`Telemetry.inbox` (the one hand-off from its threads;
the tuples are those of :mod:`groundstation.flight.link`, plus ``("abort", t, cause)`` from a
signal handler). :meth:`Telemetry.collect` drains it into the journal's pending rows and counts
each block's packets and firmware times for the summary; it keeps the last battery voltage (the
take-off check) and altitude (the altitude hold).

**Watches** (while flying): a measured rate beyond :class:`RateLimits` for its number of
consecutive samples, the firmware's power management reporting low power (``pm.state``: the
battery running out), and silence: no log packet for :data:`LINK_SILENCE_S` of flight time is link
loss, after cflib's threads got :data:`_SILENCE_GRACE_S` of wall time to deliver what has already
arrived. Each is a cause in the journal; the runner aborts.
"""

from __future__ import annotations

import math
import queue
import time
from collections import defaultdict
from collections.abc import Sequence

from groundstation.flight.blocks import ALTITUDE_BLOCK, BATTERY_BLOCK, LOW_POWER
from groundstation.flight.journal import Journal
from groundstation.flight.safety import RateLimits

__all__ = ["LINK_SILENCE_S", "Telemetry"]

LINK_SILENCE_S = 0.5
"""No log packet for this long (flight clock) while flying is link loss: the flight aborts.
The three 50 Hz blocks make it 75 missing packets; the Crazyflie's own watchdog levels out
after 0.5 s without a setpoint too."""
_SILENCE_GRACE_S = 0.1  # wall s: cflib's threads get this long to deliver what has arrived


class Telemetry:
    """The inbox from cflib's threads, drained and watched (module docstring)."""

    def __init__(self, *, journal: Journal, limits: RateLimits) -> None:
        self.journal, self.limits = journal, limits
        self.inbox: queue.SimpleQueue[tuple] = queue.SimpleQueue()
        self.fw_ms: dict[str, list[int]] = defaultdict(list)  # firmware ms per log block
        self.delivered: dict[str, int] = defaultdict(int)
        self.last_log = -math.inf  # flight time of the newest log packet (any block)
        self.last_block: dict[str, float] = {}  # ... of each block
        self.vbat: float | None = None
        self.supervisor: int | None = None  # supervisor.info where a block logs it
        self.supervisor_t = -math.inf  # ... flight time it arrived
        self.supervisor_at: dict[str, int] = {}  # block -> index of supervisor.info in it
        self.pm_state: int | None = None  # pm.state where the battery block logs it
        self.pm_state_at: dict[str, int] = {}  # block -> index of pm.state in it
        self.altitude_m: float | None = None  # last logged altitude for the altitude hold
        self.over_limit_runs = [0, 0, 0]  # consecutive packets beyond the rate limit, per axis
        self.console = ""
        self.flying = False  # the watches are on
        self.landing = False  # in the plan's landing phase (low power: no abort, it lands)
        self.silent = False  # link loss found by the silence watch
        self.stop_t = math.inf  # flight time the stop setpoint went out (Commander.stop)
        self.stop_seen = False  # the motors logged at 0 after it: the vehicle has it

    def collect(self) -> None:
        """Drain the queue into pending rows; check link, signals and limits (no I/O)."""
        journal = self.journal
        while True:
            try:
                item = self.inbox.get_nowait()
            except queue.Empty:
                return
            kind, t = item[0], item[2] if item[0] == "log" else item[1]
            t -= journal.origin
            if kind == "log":
                _, block, _, fw_ms, values = item
                journal.pending[block].append((t, fw_ms, *values))
                self.last_log = self.last_block[block] = t
                self.fw_ms[block].append(fw_ms)
                self.delivered[block] += 1
                if block == BATTERY_BLOCK[0]:
                    self.vbat = float(values[0])
                elif block == ALTITUDE_BLOCK:
                    self.altitude_m = float(values[0])
                elif block == "gyro" and self.flying:
                    self._check_rates(values)
                elif block == "motors" and t > self.stop_t and not any(values):
                    self.stop_seen = True
                if block in self.supervisor_at:  # the battery's, or the attitude's
                    self.supervisor = int(values[self.supervisor_at[block]])
                    self.supervisor_t = t
                if block in self.pm_state_at:
                    self._check_power(int(values[self.pm_state_at[block]]))
            elif kind == "console":
                self.console += item[2]
                *lines, self.console = self.console.split("\n")
                for line in lines:
                    journal.event(line.rstrip(), source="console")
            elif kind == "link":
                journal.pending["link"].append((t, item[2], item[3]))
            elif kind == "lost" and journal.landed and self.stop_seen:
                journal.event(f"after landing: link lost: {item[2]} (the motors were logged "
                              "stopped after the stop setpoint)", level="warning",
                              source="safety")
            elif kind == "lost":  # a cause: reported late, it may predate the stop
                journal.cause(f"link lost: {item[2]}")
            elif kind == "abort":
                journal.stop_request(item[2], level="warning")
            else:
                journal.event(str(item[2]), level="warning", source="link")

    def _check_rates(self, values: Sequence[float]) -> None:
        lim = self.limits
        for i, v in enumerate(values):
            runs = self.over_limit_runs
            runs[i] = runs[i] + 1 if abs(v) > lim.max_rate_deg_s else 0
            if runs[i] == lim.samples and not self.journal.causes:
                self.journal.cause(f"limit: gyro.{'xyz'[i]} = {v:.0f} deg/s beyond "
                                   f"{lim.max_rate_deg_s:g} deg/s for {lim.samples} samples")

    def _check_power(self, state: int) -> None:
        """The firmware's power management says low power while flying: the battery is
        running out, and below ``pm.criticalLowVoltage`` for 5 s the firmware shuts down in
        the air; land now, while it can (in the plan's landing phase it already does: an
        event, no abort)."""
        if state == LOW_POWER and self.pm_state != LOW_POWER:
            during = "; it is landing as planned" if self.flying and self.landing else ""
            self.journal.event(f"the Crazyflie reports low power (pm.state 3){during}",
                               level="warning", source="safety")
        self.pm_state = state
        if state == LOW_POWER and self.flying and not self.landing and not self.journal.causes:
            self.journal.cause("battery low in flight: the Crazyflie's power management reports "
                               "low power (pm.state 3: below pm.lowVoltage, 3.2 V by default, "
                               "for 5 s; below pm.criticalLowVoltage, 3.0 V, for 5 s it shuts "
                               "down in the air): landing; charge or swap the battery")

    def wait(self, t: float) -> None:
        """Sleep until ``t`` on the flight clock (absolute), then take in what arrived."""
        journal = self.journal
        journal.clock.sleep_until(t)
        self.collect()
        if self.flying and not journal.causes and journal.now() - self.last_log > LINK_SILENCE_S:
            self._check_silence()

    def _check_silence(self) -> None:
        """No log packet for :data:`LINK_SILENCE_S` of flight time: give cflib's threads
        :data:`_SILENCE_GRACE_S` of wall time to deliver what has already arrived (a host
        too busy to run them is not a dead link), then call it link loss."""
        journal = self.journal
        give_up = time.monotonic() + _SILENCE_GRACE_S
        while time.monotonic() < give_up:
            time.sleep(0.01)
            self.collect()
            if journal.now() - self.last_log <= LINK_SILENCE_S or journal.causes:
                return
        self.silent = True
        journal.cause(f"link lost: no log packet for {journal.now() - self.last_log:.2f} s "
                      f"(limit {LINK_SILENCE_S:g} s)")
