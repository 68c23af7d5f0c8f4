"""Flat out (``speed=inf``) the simulation runs in lock-step with the ground station: two flights
with the same seed record the same data, bit for bit (the ``link`` stream excepted: cflib's pings
and latency are wall-clock by nature)."""

from __future__ import annotations

import h5py
import numpy as np

from groundstation.flight import fly_plan


def _streams(path) -> dict[str, np.ndarray]:
    with h5py.File(path) as f:
        return {name: f[name]["data"][()] for name in f if name != "link" and "data" in f[name]}


def test_same_seed_flights_at_speed_inf_are_identical(sim_uri, tmp_path):
    runs = [fly_plan(plan="prbs-3axis", out=tmp_path, uri=sim_uri(speed="inf", seed=4), tag=tag)
            for tag in ("a", "b")]
    for r in runs:
        r.raise_if_aborted()
    first, second = (_streams(r.path) for r in runs)
    assert first.keys() == second.keys()
    for name in first:
        assert first[name].tobytes() == second[name].tobytes(), name
