"""The simulation clock: the time line of a running simulated Crazyflie.

:func:`groundstation.flight.clock.clock_for_uri` hands a :class:`SimClock` to the flight runner for
``sim://`` URIs (registered on import of this module), so the runner's 10 Hz setpoints are scheduled
on the vehicle's own time, however fast the simulation runs.

``now()`` is the vehicle's simulation time in seconds. ``sleep_until(t)`` waits until the simulation
has reached ``t``, which is ``(t - now()) / speed`` seconds of wall time while the simulation keeps
up, and never lets the runner get ahead of the vehicle when it does not. Once the simulation has
stopped the clock carries on as the host clock scaled by ``speed``, so it stays monotonic and
``sleep_until`` never hangs.

Pacing: a scheduler that sleeps on this clock also paces the simulation
(:meth:`groundstation.sim.simulator.Simulator.pace`): simulated time runs at most a few ms past the
time the scheduler asked to wake at, and waits (up to 3 s of wall time, or until the link
detaches) for it to sleep again. A host briefly too busy to wake the runner therefore freezes
simulated time, as a faster host would, instead of delaying setpoints in simulated time.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Protocol

from groundstation.flight.clock import Clock, register_clock

__all__ = ["SimClock", "TimeSource"]

_FALLBACK_SPEED = 1000.0  # speed of a stopped clock whose simulation ran "as fast as possible"


class TimeSource(Protocol):
    """What a :class:`SimClock` reads: the simulation's published time and its condition."""

    speed: float
    cond: threading.Condition

    @property
    def published_s(self) -> float:
        """Simulation seconds reached so far (read under ``cond``)."""
        ...

    @property
    def running(self) -> bool:
        """Whether the simulation thread is still advancing time."""
        ...


class SimClock:
    """The :class:`groundstation.flight.clock.Clock` of one simulation (``speed`` sim s per wall
    s)."""

    def __init__(self, *, source: TimeSource) -> None:
        self._source = source
        self.speed = source.speed
        self._stopped_at: tuple[float, float] | None = None  # (sim s, wall s) when it stopped

    def _fallback_speed(self) -> float:
        return _FALLBACK_SPEED if math.isinf(self.speed) else self.speed

    def now(self) -> float:
        src = self._source
        with src.cond:
            if src.running:
                return src.published_s
            if self._stopped_at is None:
                self._stopped_at = (src.published_s, time.monotonic())
        sim_s, wall_s = self._stopped_at
        return sim_s + (time.monotonic() - wall_s) * self._fallback_speed()

    def sleep_until(self, t: float) -> None:
        src = self._source
        pace = getattr(src, "pace", None)
        if pace is not None:
            pace(until_s=t)
        with src.cond:  # flat out also until the simulation holds for this sleep and the link
            # has delivered what it released by then (Simulator.quiescent: lock-step)
            while src.running and (src.published_s < t or not getattr(src, "quiescent", True)):
                src.cond.wait(0.05)
        remaining = t - self.now()
        if remaining > 0:
            time.sleep(remaining / self._fallback_speed())


def _clock_for(uri: str) -> Clock | None:
    from groundstation.sim.registry import simulator_for_uri

    return simulator_for_uri(uri).clock


register_clock("sim", _clock_for)
