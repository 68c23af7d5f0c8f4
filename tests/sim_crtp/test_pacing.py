"""A scheduler sleeping on the simulation clock paces the simulation: a busy host freezes
simulated time instead of making the scheduler late in it."""

from __future__ import annotations

import time

import pytest

from groundstation.flight.clock import clock_for_uri
from groundstation.sim.simulator import _PACE_HOLD_S, _PACE_LEAD_MS


def test_busy_scheduler_freezes_simulated_time(sim_uri):
    clock = clock_for_uri(sim_uri)  # speed 20: 0.1 s wall would be 2 s of simulated time
    t = clock.now() + 0.5
    clock.sleep_until(t)
    assert clock.now() >= t
    time.sleep(0.1)  # the "runner" is busy (GIL, I/O) and does not sleep on the clock
    assert clock.now() - t <= _PACE_LEAD_MS / 1000 + 0.011  # held at the lead (+1 step)
    clock.sleep_until(t + 0.1)  # sleeping again releases it to the next deadline
    assert t + 0.1 <= clock.now() <= t + 0.1 + 0.05


def test_hold_is_released_when_the_scheduler_goes_away(sim_uri):
    clock = clock_for_uri(sim_uri)
    t = clock.now() + 0.2
    clock.sleep_until(t)
    time.sleep(_PACE_HOLD_S + 0.3)  # gone longer than the hold: the vehicle lives on
    assert clock.now() - t > 1.0
    assert clock.speed == pytest.approx(20.0)
