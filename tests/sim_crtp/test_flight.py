"""Flying the simulated Crazyflie through cflib's Commander: signs, thrust lock, watchdog, hover.

Known truth: the firmware conventions in docs/simulator.md and crazyflie-facts.md (cflib negates
pitch; a positive ``send_setpoint`` pitch tilts the nose down: ``gyro.y`` > 0, legacy
``stabilizer.pitch`` < 0), the supervisor's 500 ms / 2 s watchdog, and the hover thrust computed
here from the documented thrust curve and mass, independently of the simulator's code.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import groundstation.sim as gsim

from .helpers import Recorder, connect, fly

STATE = {"state": ["stabilizer.roll", "stabilizer.pitch", "stateEstimate.z", "pm.vbat",
                   "stabilizer.thrust"]}
FLIGHT = {"gyro": ["gyro.x", "gyro.y", "gyro.z"], "acc": ["acc.x", "acc.y", "acc.z"],
          "motors": [f"motor.m{i}" for i in range(1, 5)], **STATE}
_C = (-0.024765, 0.065238, -0.026793, 0.0067768)  # thrust per motor (N) in v = vbat pwm / 65535
_MASS_KG = 0.028


def hover_thrust(vbat: float) -> int:
    """PWM at which four motors carry 0.028 kg (bisection on the documented cubic)."""
    lo, hi = 0.0, 65535.0
    for _ in range(50):
        mid = (lo + hi) / 2
        v = vbat * mid / 65535
        f = _C[0] + v * (_C[1] + v * (_C[2] + v * _C[3]))
        lo, hi = (mid, hi) if 4 * f < _MASS_KG * 9.81 else (lo, mid)
    return int(lo)


def _window(rec: Recorder, name: str, t0_s: float, t1_s: float) -> tuple[np.ndarray, np.ndarray]:
    t, v = rec.rows(name)
    keep = (t >= t0_s * 1000) & (t < t1_s * 1000)
    return t[keep] / 1000.0, v[keep]


def test_pitch_setpoint_gives_documented_gyro_sign(sim_uri):
    with connect(sim_uri) as scf:
        cf, clock = scf.cf, gsim.instance(sim_uri).clock
        rec = Recorder(scf.cf, blocks=FLIGHT)
        thrust = int(1.3 * hover_thrust(4.0))
        fly(cf, clock, [(0.2, 0, 0, 0, 0), (1.0, 0, 0, 0, thrust)])
        t_step = clock.now()
        fly(cf, clock, [(1.0, 0, 10, 0, thrust), (0.2, 0, 0, 0, 0)])
    _, gyro = _window(rec, "gyro", t_step, t_step + 1.0)
    _, state = _window(rec, "state", t_step + 0.7, t_step + 1.0)
    assert gyro[:, 1].max() > 30.0  # deg/s, nose going down ...
    assert gyro[:, 1].max() > 3 * abs(gyro[:, 1].min())  # ... not up
    assert np.abs(gyro[:, 0]).max() < 0.25 * gyro[:, 1].max()  # and not rolling
    assert np.mean(state[:, 1]) == pytest.approx(-10.0, abs=2.0)  # legacy pitch, nose down < 0


def test_thrust_lock_until_a_zero_thrust_setpoint(sim_uri):
    with connect(sim_uri) as scf:
        cf, clock = scf.cf, gsim.instance(sim_uri).clock
        rec = Recorder(scf.cf, blocks={"motors": FLIGHT["motors"]})
        t0 = clock.now()
        fly(cf, clock, [(1.0, 0, 0, 0, 30000)])
        t1 = clock.now()
        fly(cf, clock, [(0.2, 0, 0, 0, 0), (0.5, 0, 0, 0, 30000)])
        t2 = clock.now()
        fly(cf, clock, [(0.2, 0, 0, 0, 0)])
    _, locked = _window(rec, "motors", t0, t1)
    _, released = _window(rec, "motors", t1, t2 + 0.3)
    assert len(locked) > 40 and not locked.any()
    assert (released > 20000).all(axis=1).sum() > 10


def test_watchdog_levels_out_then_stops_motors_and_locks(sim_uri):
    with connect(sim_uri) as scf:
        cf, sim = scf.cf, gsim.instance(sim_uri)
        clock = sim.clock
        rec = Recorder(scf.cf, blocks=FLIGHT)
        thrust = int(1.05 * hover_thrust(4.0))
        fly(cf, clock, [(0.2, 0, 0, 0, 0), (0.6, 0, 0, 0, int(1.4 * thrust)),
                        (1.0, 8, 0, 0, thrust)])
        t_sent = clock.now() - 0.1  # the last setpoint went out one period ago
        assert sim.vehicle.is_flying
        while not sim.vehicle.is_locked and clock.now() < t_sent + 6.0:
            clock.sleep_until(clock.now() + 0.1)
        assert sim.vehicle.is_locked and sim.vehicle.motors_pwm == (0, 0, 0, 0)
        assert sim.vehicle.stop_count >= 1
        clock.sleep_until(clock.now() + 0.5)
    t, motors = _window(rec, "motors", t_sent, t_sent + 10)
    t_stop = t[np.argmax(~motors.any(axis=1))]  # first sample with all motors off
    t_last = t_stop - 2.0  # when the vehicle got its last setpoint, by the 2 s rule
    assert t_sent - 0.05 <= t_last <= t_sent + 1.0  # setpoints reach it late under load only
    _, tilted = _window(rec, "state", t_last - 0.3, t_last + 0.4)
    _, level = _window(rec, "state", t_last + 1.2, t_last + 1.9)
    _, running = _window(rec, "motors", t_last + 0.6, t_last + 1.9)
    _, stopped = _window(rec, "motors", t_stop, t_stop + 0.5)
    assert np.mean(tilted[:, 0]) == pytest.approx(8.0, abs=2.0)
    assert np.abs(level[:, 0]).max() < 2.0  # levelled out after 500 ms without setpoints
    assert (running > 0).all()  # ... with the motors still running
    assert len(stopped) > 20 and not stopped.any()  # 2 s: motors stopped for good


def test_hover_at_the_known_thrust(sim_uri):
    with connect(sim_uri) as scf:
        cf, clock = scf.cf, gsim.instance(sim_uri).clock
        rec = Recorder(scf.cf, blocks=FLIGHT)
        fly(cf, clock, [(0.2, 0, 0, 0, 0), (0.2, 0, 0, 0, 10001)])
        _, state = rec.rows("state")
        vbat = float(state[-1, 3])
        climb = int(1.25 * hover_thrust(vbat))
        fly(cf, clock, [(0.8, 0, 0, 0, climb)])
        _, state = rec.rows("state")
        hover = hover_thrust(float(state[-1, 3]))
        fly(cf, clock, [(2.0, 0, 0, 0, hover), (0.2, 0, 0, 0, 0)])
    t, state = rec.rows("state")
    _, acc = rec.rows("acc")
    n = min(len(t), len(acc))
    t, state, acc = t[:n] / 1000.0, state[:n], acc[:n]
    at_hover = np.flatnonzero(state[:, 4] == hover)  # stabilizer.thrust: what the vehicle got
    at_climb = np.flatnonzero(state[:, 4] == climb)
    assert t[at_hover[-1]] - t[at_hover[0]] > 1.5 and len(at_climb) > 20
    hover_rows = at_hover[t[at_hover] > t[at_hover[0]] + 0.3]  # skip the motors' transient
    accel_hover = 2 * np.polyfit(t[hover_rows] - t[hover_rows[0]], state[hover_rows, 2], 2)[0]
    accel_climb = 2 * np.polyfit(t[at_climb] - t[at_climb[0]], state[at_climb, 2], 2)[0]
    assert state[hover_rows, 2].min() > 0.05  # airborne
    assert abs(accel_hover) < 0.6  # m/s^2: the weight is carried
    assert accel_climb > 1.5
    assert np.mean(acc[hover_rows, 2]) == pytest.approx(1.0, abs=0.05)  # specific force 1 g
    assert math.isfinite(vbat) and 3.5 < vbat < 4.3
