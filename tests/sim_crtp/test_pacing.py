"""A scheduler sleeping on the simulation clock paces the simulation: a busy host freezes
simulated time instead of making the scheduler late in it."""

from __future__ import annotations

import time

import pytest

from groundstation.flight.clock import clock_for_uri
from groundstation.sim import simulator
from groundstation.sim.simulator import _PACE_HOLD_S, _PACE_LEAD_MS


@pytest.mark.parametrize("speed", ["20", "inf"])
def test_busy_scheduler_freezes_simulated_time(sim_uri, speed):
    """At 20x, 0.1 s of wall time would be 2 s of simulated time; flat out, about 4 s."""
    clock = clock_for_uri(sim_uri.replace("speed=20", f"speed={speed}"))
    t = clock.now() + 0.5
    clock.sleep_until(t)
    assert clock.now() >= t
    time.sleep(0.1)  # the "runner" is busy (GIL, I/O) and does not sleep on the clock
    assert clock.now() - t <= _PACE_LEAD_MS / 1000 + 0.011  # held at the lead (+1 step)
    clock.sleep_until(t + 0.1)  # sleeping again releases it to the next deadline
    assert t + 0.1 <= clock.now() <= t + 0.1 + 0.05


def test_hold_is_released_when_the_scheduler_goes_away(sim_uri, monkeypatch):
    # The hold's length is a constant of the simulator (3 s); a shorter one here, read the
    # same way, so the test waits 0.8 s instead of 3.3 s.
    hold_s = 0.5
    monkeypatch.setattr(simulator, "_PACE_HOLD_S", hold_s)
    assert hold_s < _PACE_HOLD_S
    clock = clock_for_uri(sim_uri)
    t = clock.now() + 0.2
    clock.sleep_until(t)
    time.sleep(hold_s + 0.3)  # gone longer than the hold: the vehicle lives on
    assert clock.now() - t > 1.0
    assert clock.speed == pytest.approx(20.0)
