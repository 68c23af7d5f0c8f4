"""Helpers for the physics tests: fly a SimVehicle with setpoints at 100 Hz and record logs."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.sim.vehicle import SimVehicle

LOGGED = ("gyro.x", "gyro.y", "gyro.z", "acc.x", "acc.y", "acc.z",
          "stabilizer.roll", "stabilizer.pitch", "stabilizer.yaw")


def fly(v: SimVehicle, *, seconds: float, roll: float = 0.0, pitch: float = 0.0,
        yawrate: float = 0.0, thrust: int | None = None, setpoints: bool = True) -> np.ndarray:
    """Advance ``seconds`` at 100 Hz, sending one RPYT setpoint per 10 ms (values as on the
    wire; ``thrust`` defaults to the hover thrust). Returns the logs, shape (n, len(LOGGED) + 3):
    LOGGED columns then position x, y, z (m)."""
    thrust = v.hover_thrust() if thrust is None else thrust
    rows = []
    for _ in range(round(seconds * 100)):
        if setpoints:
            v.commander_rpyt(roll=roll, pitch=pitch, yawrate=yawrate, thrust=thrust)
        v.advance(0.01)
        rows.append([v.read_log(n) for n in LOGGED] + list(v.position_m))
    return np.array(rows)


@pytest.fixture
def hovering() -> SimVehicle:
    """A vehicle released at 0.5 m with the thrust lock already released."""
    v = SimVehicle(seed=7, start_z_m=0.5)
    v.commander_rpyt(roll=0.0, pitch=0.0, yawrate=0.0, thrust=0)
    return v
