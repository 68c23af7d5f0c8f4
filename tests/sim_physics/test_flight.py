"""Closed-loop behaviour a user observes: hover, attitude steps and their signs, ground, battery."""

from __future__ import annotations

import numpy as np

from groundstation.sim.vehicle import SimVehicle
from tests.sim_physics.conftest import LOGGED, fly

GX, GY, GZ, AX, AY, AZ, ROLL, PITCH, YAW = range(9)
X, Y, Z = len(LOGGED), len(LOGGED) + 1, len(LOGGED) + 2


def test_hover_thrust_holds_altitude_and_attitude(hovering):
    h = hovering.hover_thrust()
    assert 36000 < h < 42000            # documented: 39153 for 28 g
    log = fly(hovering, seconds=5.0)
    assert np.abs(log[:, Z] - 0.5).max() < 0.03
    assert np.hypot(log[:, X], log[:, Y]).max() < 0.05
    assert np.abs(log[:, [ROLL, PITCH]]).max() < 1.0
    assert hovering.is_flying and hovering.supervisor_state == "Flying"


def test_hover_thrust_is_weight_dependent():
    light, heavy = SimVehicle(mass_kg=0.027), SimVehicle(mass_kg=0.032)
    assert heavy.hover_thrust() > light.hover_thrust() + 1500
    v = SimVehicle(mass_kg=0.032, start_z_m=0.5)
    v.commander_rpyt(roll=0, pitch=0, yawrate=0, thrust=0)
    log = fly(v, seconds=1.0, thrust=light.hover_thrust())
    assert log[-1, Z] < 0.4                # too little thrust for the heavier vehicle: sinks


def test_wire_pitch_minus_10_tilts_nose_down_with_positive_gyro_y(hovering):
    # cflib send_setpoint(pitch=+10) puts -10 on the wire.
    log = fly(hovering, seconds=3.0, pitch=-10.0)
    assert log[:20, GY].mean() > 10.0               # nose-down rotation: +y (left) right-handed
    assert abs(log[:20, GX].mean()) < 2.0
    assert abs(log[-50:, PITCH].mean() + 10.0) < 1.0   # legacy pitch: nose down is negative
    vx, *_ = hovering.velocity_m_s
    assert vx > 0.5 and log[-1, X] > 0.3            # flies forward
    assert log[-50:, AX].mean() < -0.02             # rotor drag shows on body acc.x


def test_wire_roll_plus_10_gives_positive_gyro_x_and_moves_right(hovering):
    log = fly(hovering, seconds=3.0, roll=10.0)
    assert log[:20, GX].mean() > 10.0
    assert abs(log[-50:, ROLL].mean() - 10.0) < 1.0
    assert log[-1, Y] < -0.3                         # right wing down: moves to -y
    assert log[-50:, AY].mean() > 0.02


def test_positive_yawrate_gives_positive_gyro_z(hovering):
    log = fly(hovering, seconds=2.0, yawrate=30.0)
    assert 20.0 < log[-100:, GZ].mean() < 40.0
    assert log[-1, YAW] > 35.0


def test_rests_on_ground_before_takeoff_and_lifts_off_above_hover():
    v = SimVehicle(seed=1)
    log = fly(v, seconds=1.0, thrust=0)
    assert np.all(log[:, Z] == 0.0)
    assert abs(log[:, AZ].mean() - 1.0) < 0.01      # +1 g at rest, body z up
    assert np.abs(log[:, [AX, AY]].mean(axis=0)).max() < 0.02
    log = fly(v, seconds=1.0, thrust=v.hover_thrust() - 3000)   # below hover: stays down
    assert np.all(log[:, Z] == 0.0) and v.is_flying
    log = fly(v, seconds=1.0, thrust=v.hover_thrust() + 6000)
    assert log[-1, Z] > 0.2


def test_no_fall_through_ground_after_motor_stop():
    v = SimVehicle(seed=2, start_z_m=0.3)
    fly(v, seconds=0.1, thrust=0)                    # releases lock, motors off: falls
    log = fly(v, seconds=1.0, thrust=0)
    assert log[:, Z].min() == 0.0 and log[-1, Z] == 0.0
    assert abs(log[-20:, AZ].mean() - 1.0) < 0.02


def test_battery_sags_under_load_and_recovers():
    v = SimVehicle(seed=3, vbat_full=4.15)
    fly(v, seconds=0.5, thrust=0)
    rest = v.read_log("pm.vbat")
    fly(v, seconds=3.0, thrust=45000)
    loaded = v.read_log("pm.vbat")
    fly(v, seconds=0.5, thrust=0)
    after = v.read_log("pm.vbat")
    assert 0.15 < rest - loaded < 0.6          # real CF2.1 in CrazyPAD: 0.29 V at hover
    assert loaded < after < rest               # recovers, minus the charge used
    assert v.read_log("pm.vbatMV") == round(after * 1000)


def test_motor_logs_carry_mixer_output_and_compensated_pwm(hovering):
    fly(hovering, seconds=0.5)
    m = np.array([hovering.read_log(f"motor.m{i}") for i in range(1, 5)])
    pwm = np.array([hovering.read_log(f"pwm.m{i}_pwm") for i in range(1, 5)])
    assert np.allclose(m.mean(), hovering.hover_thrust(), rtol=0.02)
    assert np.all(pwm > m)                     # vbat > motor voltage wanted: duty above command
    assert tuple(int(x) for x in m) == hovering.motors_pwm


def test_deterministic_for_a_seed():
    a = fly(SimVehicle(seed=5, start_z_m=0.5), seconds=0.5, thrust=0)
    b = fly(SimVehicle(seed=5, start_z_m=0.5), seconds=0.5, thrust=0)
    c = fly(SimVehicle(seed=6, start_z_m=0.5), seconds=0.5, thrust=0)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
