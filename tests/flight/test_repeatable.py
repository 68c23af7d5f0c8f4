"""Flat out (``speed=inf``) the simulation runs in lock-step with the ground station: two flights
with the same seed record the same data, bit for bit (the ``link`` stream excepted: cflib's pings
and latency are wall-clock by nature)."""

from __future__ import annotations

import h5py
import numpy as np

from groundstation.flight import fly_plan

from .checks import check_closed_with_stop, safety_events
from .conftest import plan_variant


def _streams(path) -> dict[str, np.ndarray]:
    with h5py.File(path) as f:
        return {name: f[name]["data"][()] for name in f if name != "link" and "data" in f[name]}


def test_same_seed_flights_at_speed_inf_are_identical(sim_uri, tmp_path):
    """prbs-3axis with 20.5 s of its PRBS (every phase, all three axes excited; the 102.3 s of
    the shipped plan cost 4 s a flight and add no path: the lock-step is per setpoint)."""
    plan = plan_variant("prbs-3axis", **{"duration = 102.3": "duration = 20.5"})
    runs = [fly_plan(plan=plan, out=tmp_path, uri=sim_uri(speed="inf", seed=4), tag=tag)
            for tag in ("a", "b")]
    for r in runs:
        r.raise_if_aborted()
    first, second = (_streams(r.path) for r in runs)
    assert first.keys() == second.keys()
    for name in first:
        assert first[name].tobytes() == second[name].tobytes(), name



def test_a_lost_link_flat_out_is_recorded_on_the_simulation_clock(sim_uri, tmp_path):
    """Flat out, a link cut at 5 s of simulated time is recorded as lost at the first setpoint
    deadline after it, at the same time in two same-seed runs. It was recorded 0.3-26 s late, a
    different time each run: once cflib closed the lost link, simulation time ran free until
    the flight heard of the loss (~80 ms of wall time later). (Flat out, connecting costs no
    simulated time: the flight clock starts at the vehicle's boot, within a few ms.)"""
    times = []
    for tag in ("a", "b"):
        result = fly_plan(plan="hover-check", out=tmp_path, tag=tag,
                          uri=sim_uri(speed="inf", seed=1, cut_at=5.0))
        assert result.aborted and result.cause.startswith("link lost"), result.cause
        s = check_closed_with_stop(result)
        lost = [e.t for e in safety_events(s) if e.text.startswith("link lost")]
        assert lost, [e.text for e in safety_events(s)]
        times.append(lost[0])
    assert 5.0 < times[0] < 5.0 + 0.1 + 0.05, times  # hover-check's setpoints: 10 Hz
    assert times[0] == times[1], times
