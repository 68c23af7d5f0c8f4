"""Firmware emulation: mixer, PID, battery compensation, commander and supervisor behaviour."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.importers import read_usd
from groundstation.sim.firmware import (
    RATE_LIMIT,
    ImuFilter,
    Pid,
    PidController,
    battery_compensated_pwm,
    mix_legacy_x,
)
from groundstation.sim.vehicle import SimConfigError, SimVehicle
from tests.paths import CRAZYPAD, needs_crazypad
from tests.sim_physics.conftest import fly


def test_mixer_signs_and_reduce_all_four_rule():
    assert mix_legacy_x(thrust=30000, roll=2000, pitch=0, yaw=0) == (29000, 29000, 31000, 31000)
    assert mix_legacy_x(thrust=30000, roll=0, pitch=2000, yaw=0) == (31000, 29000, 29000, 31000)
    assert mix_legacy_x(thrust=30000, roll=0, pitch=0, yaw=500) == (30500, 29500, 30500, 29500)
    # m1 = 64000 - 0 + 3000 = 67000 exceeds 65535 by 1465: all four lose 1465.
    m = mix_legacy_x(thrust=64000, roll=0, pitch=6000, yaw=0)
    assert m == (65535, 61000 - 1465, 61000 - 1465, 65535)
    assert mix_legacy_x(thrust=1000, roll=0, pitch=-6000, yaw=0)[0] == 0    # clipped at 0


@needs_crazypad
def test_battery_compensation_matches_the_real_log():
    ev = read_usd(f"{CRAZYPAD}/motor_E8_log00").events["fixedFrequency"]
    m, pwm = ev.values["motor.m1"].astype(float), ev.values["pwm.m1_pwm"].astype(float)
    vbat = ev.values["pm.vbatMV"].astype(float) / 1000.0
    on = np.flatnonzero(m > 20000)[::50]
    sim = np.array([battery_compensated_pwm(ithrust=m[i], vbat_v=vbat[i]) for i in on])
    # The firmware uses its filtered vbat, the log the 100 Hz sample: agree to 1 %.
    assert np.abs(sim / pwm[on] - 1.0).max() < 0.01
    assert battery_compensated_pwm(ithrust=60000, vbat_v=2.8) == 65535   # saturates


def test_pid_integral_limit_and_output_saturation():
    pid = Pid(kp=250.0, ki=500.0, kd=0.0, i_limit=33.3, out_limit=RATE_LIMIT, dt=0.002,
              cutoff_hz=20.0)
    for _ in range(10000):
        out = pid.update(1000.0)
    assert pid.integ == pytest.approx(33.3)
    assert out == RATE_LIMIT
    pid.reset()
    assert pid.update(1.0) == pytest.approx(250.0 + 500.0 * 0.002, rel=0.01)


def _gain(filt_apply, *, f_hz: float, rate_hz: float = 500.0) -> float:
    """Steady-state gain of a filter at ``f_hz`` (a sine through it, the last second)."""
    t = np.arange(int(3 * rate_hz)) / rate_hz
    out = np.array([filt_apply(x) for x in np.sin(2 * np.pi * f_hz * t)])
    return float(np.ptp(out[-int(rate_hz):]) / 2)


def test_sensor_filters_and_rate_loop_are_the_firmwares():
    """The firmware low-passes the gyro at 80 Hz and the accelerometer at 30 Hz (``lpf2p``,
    Butterworth: -3 dB at the cut-off) and leaves the rate loop's D term unfiltered
    (``ATTITUDE_RATE_LPF_ENABLE`` false): what the rate loop differentiates is the filtered gyro."""
    imu = ImuFilter(rate_hz=500.0)
    assert imu.az == 1.0
    for _ in range(50):  # at rest from power-on: no start transient on the 1 g
        imu.update(gx=0.0, gy=0.0, gz=0.0, ax=0.0, ay=0.0, az=1.0)
        assert imu.az == pytest.approx(1.0, abs=1e-12)
    gyro, acc = ImuFilter(rate_hz=500.0), ImuFilter(rate_hz=500.0)

    def g(x: float) -> float:
        gyro.update(gx=x, gy=0.0, gz=0.0, ax=0.0, ay=0.0, az=1.0)
        return gyro.gx

    def a(x: float) -> float:
        acc.update(gx=0.0, gy=0.0, gz=0.0, ax=x, ay=0.0, az=1.0)
        return acc.ax

    assert _gain(g, f_hz=2.0) == pytest.approx(1.0, abs=0.01)
    assert _gain(g, f_hz=80.0) == pytest.approx(2 ** -0.5, abs=0.02)
    assert _gain(a, f_hz=30.0) == pytest.approx(2 ** -0.5, abs=0.02)
    assert _gain(a, f_hz=80.0) < 0.2
    pids = PidController().pids
    assert not any(pids[f"{axis}_rate"].filtered for axis in ("roll", "pitch", "yaw"))


def test_thrust_lock_until_a_zero_thrust_setpoint():
    v = SimVehicle(seed=1)
    fly(v, seconds=0.5, thrust=45000)
    assert v.motors_pwm == (0, 0, 0, 0) and v.position_m[2] == 0.0
    fly(v, seconds=0.05, thrust=0)
    fly(v, seconds=0.2, thrust=45000)
    assert min(v.motors_pwm) > 40000
    fly(v, seconds=0.2, thrust=500)              # below MIN_THRUST: motors off, no lock
    assert v.motors_pwm == (0, 0, 0, 0)
    fly(v, seconds=0.05, thrust=65000)           # clamped to 60000
    assert v.read_log("stabilizer.thrust") == 60000


def test_watchdog_levels_out_after_500_ms_then_locks_after_2_s(hovering):
    fly(hovering, seconds=1.5, roll=15.0)
    assert hovering.attitude_deg[0] > 12.0
    fly(hovering, seconds=0.45, setpoints=False)
    assert hovering.attitude_deg[0] > 12.0 and hovering.supervisor_state == "Flying"
    fly(hovering, seconds=0.5, setpoints=False)
    assert abs(hovering.attitude_deg[0]) < 3.0          # levelled, thrust kept
    assert hovering.supervisor_state == "WarningLevelOut" and min(hovering.motors_pwm) > 30000
    fly(hovering, seconds=1.1, setpoints=False)
    assert hovering.is_locked and hovering.motors_pwm == (0, 0, 0, 0)
    assert hovering.stop_count == 1 and hovering.supervisor_state == "Locked"
    assert any("Locked" in line for line in hovering.drain_console())
    fly(hovering, seconds=0.1, thrust=0)
    fly(hovering, seconds=0.5)                            # locked until re-created
    assert hovering.motors_pwm == (0, 0, 0, 0)


def test_level_out_relocks_thrust(hovering):
    fly(hovering, seconds=0.5)
    fly(hovering, seconds=0.6, setpoints=False)           # > 500 ms: priority disabled
    fly(hovering, seconds=0.1)                            # thrust > 0 straight away: locked
    assert hovering.motors_pwm == (0, 0, 0, 0)
    fly(hovering, seconds=0.02, thrust=0)
    fly(hovering, seconds=0.1)
    assert min(hovering.motors_pwm) > 30000


def test_one_stop_setpoint_then_silence_locks_as_the_firmware_does(hovering):
    """The stop stops the motors, but the supervisor counts the vehicle as flying 2 s longer;
    a commander silent meanwhile levels out at 0.5 s and locks at 2 s (``supervisor.c``)."""
    fly(hovering, seconds=0.5)
    hovering.commander_stop()
    hovering.advance(0.004)
    assert hovering.motors_pwm == (0, 0, 0, 0) and hovering.stop_count == 1
    hovering.advance(0.6)
    assert hovering.supervisor_state == "WarningLevelOut" and hovering.is_flying
    hovering.advance(1.5)
    assert hovering.is_locked and hovering.supervisor_state == "Locked"
    assert hovering.read_log("supervisor.info") == 0x44  # locked, auto-arm (SITL: 68)


def test_stop_setpoints_fed_until_landed_leave_the_vehicle_unlocked(hovering):
    fly(hovering, seconds=0.5)
    fed = 0
    while hovering.is_flying and fed < 50:
        hovering.commander_stop()
        hovering.advance(0.1)
        fed += 1
    assert hovering.supervisor_state == "Landed" and 20 <= fed <= 21  # 2 s after the motors
    assert hovering.read_log("supervisor.info") == 0b1110  # armed, auto-arm, can fly (SITL: 14)
    hovering.advance(2.0)                                  # then silence: no lock
    assert not hovering.is_locked and hovering.supervisor_state == "Landed"
    hovering.advance(1.1)
    assert hovering.supervisor_state == "ReadyToFly"       # LANDING_TIMEOUT_MS later
    fly(hovering, seconds=0.02, thrust=0)
    fly(hovering, seconds=0.3)
    assert min(hovering.motors_pwm) > 30000 and hovering.supervisor_state == "Flying"


def test_an_emergency_stop_in_landed_locks_only_at_the_landing_timeout(hovering):
    """``supervisor_state_machine.c``: every state but *Landed* leaves for *Locked* (through
    *ExceptFreeFall*) on an emergency stop; *Landed* has no such transition, and its landing
    timeout resets it into a state that has: the lock comes 3 s after the landing."""
    fly(hovering, seconds=0.5)
    while hovering.is_flying:
        hovering.commander_stop()
        hovering.advance(0.1)
    assert hovering.supervisor_state == "Landed"
    hovering.emergency_stop()
    hovering.advance(2.8)
    assert hovering.supervisor_state == "Landed" and not hovering.is_locked
    hovering.advance(0.4)
    assert hovering.is_locked and hovering.read_log("supervisor.info") == 0x44
    fly(hovering, seconds=0.1, thrust=0)
    fly(hovering, seconds=0.3)
    assert hovering.motors_pwm == (0, 0, 0, 0)


def test_the_emergency_stop_watchdog_locks_a_second_after_its_last_notification(hovering):
    """``supervisor.c`` ``checkEmergencyStopWatchdog``: off until its first notification,
    then an emergency stop whenever the last one is more than 1 s old."""
    fly(hovering, seconds=1.5)
    hovering.emergency_stop_watchdog()
    for _ in range(3):
        fly(hovering, seconds=0.9)
        hovering.emergency_stop_watchdog()
    assert min(hovering.motors_pwm) > 30000 and not hovering.is_locked
    fly(hovering, seconds=0.95)
    assert min(hovering.motors_pwm) > 30000
    fly(hovering, seconds=0.1)
    assert hovering.is_locked and hovering.motors_pwm == (0, 0, 0, 0)
    assert hovering.drain_console()[-1] == (
        "SUPERVISOR: Locked due to an emergency stop, reboot required\n")


def test_notify_stop_lets_the_setpoint_expire(hovering):
    fly(hovering, seconds=2.5)       # the firmware cannot age a setpoint past power-on
    hovering.commander_notify_stop(remain_valid_ms=100)
    hovering.advance(0.09)
    assert min(hovering.motors_pwm) > 30000
    hovering.advance(0.02)
    assert hovering.motors_pwm == (0, 0, 0, 0)


def test_a_vehicle_that_does_not_arm_itself_is_disarmed_at_the_landing_timeout():
    """``supervisor.c``: Landed, 3 s later Reset, which disarms; a CF2.x re-arms itself at
    once, a Brushless stays disarmed until asked again."""
    v = SimVehicle(seed=1, auto_arm=False, start_z_m=0.5)
    v.arm(armed=True)
    fly(v, seconds=0.02, thrust=0)
    fly(v, seconds=0.5)
    assert v.supervisor_state == "Flying"
    while v.is_flying:
        v.commander_stop()
        v.advance(0.1)
    assert v.supervisor_state == "Landed" and v.read_log("supervisor.info") == 0b1010
    v.advance(3.1)
    assert v.supervisor_state == "PreFlChecksPassed" and v.read_log("supervisor.info") == 0b0001
    fly(v, seconds=0.3)
    assert v.motors_pwm == (0, 0, 0, 0)  # not armed: no motors until armed again


def test_disarmed_vehicle_keeps_motors_off():
    v = SimVehicle(seed=1, auto_arm=False)
    assert v.supervisor_state == "PreFlChecksPassed"
    fly(v, seconds=0.05, thrust=0)
    fly(v, seconds=0.2, thrust=45000)
    assert v.motors_pwm == (0, 0, 0, 0)
    v.arm(armed=True)
    fly(v, seconds=0.2, thrust=45000)
    assert min(v.motors_pwm) > 40000


def test_params_read_write_change_behaviour(hovering):
    assert hovering.read_param("pid_rate.roll_kp") == 250.0
    assert hovering.read_param("pid_attitude.yaw_kd") == 0.35
    hovering.write_param("pid_attitude.roll_kp", 0.0)
    hovering.write_param("pid_attitude.roll_ki", 0.0)
    log = fly(hovering, seconds=1.0, roll=10.0)
    assert abs(log[-1, 6]) < 1.0                         # no attitude loop: roll not tracked
    hovering.write_param("stabilizer.stop", 1)
    fly(hovering, seconds=0.05)
    assert hovering.motors_pwm == (0, 0, 0, 0)
    assert hovering.is_locked and hovering.read_log("supervisor.info") == 0x44  # as the firmware
    assert hovering.drain_console()[-1] == (
        "SUPERVISOR: Locked due to an emergency stop, reboot required\n")  # no timeout's
    rev = hovering.read_param("firmware.revision0")
    hovering.write_param("firmware.revision0", 1)        # read-only: ignored
    assert hovering.read_param("firmware.revision0") == rev
    with pytest.raises(KeyError, match=r"pid_rate\.nope"):
        hovering.write_param("pid_rate.nope", 1.0)


def test_log_and_param_tables_are_complete():
    v = SimVehicle()
    for name in v.LOG_VARIABLES:
        assert isinstance(v.read_log(name), float)
    for name in v.PARAMS:
        assert isinstance(v.read_param(name), float)
    assert v.LOG_VARIABLES["motor.m1"] == "uint16_t" and v.LOG_VARIABLES["pm.vbat"] == "float"
    assert v.firmware_ms == 0 and v.time_s == 0.0
    v.advance(0.0204)
    assert v.firmware_ms == 20 and v.time_s == pytest.approx(0.020)
    assert v.drain_console() and v.drain_console() == []


def test_unknown_override_is_a_one_line_error():
    with pytest.raises(SimConfigError, match=r"unknown simulator option.*mass"):
        SimVehicle(mass=0.03)
    with pytest.raises(SimConfigError, match="vbat_full"):
        SimVehicle(vbat_full=5.0)



def _yawing(v: SimVehicle, *, seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Yawing at 60 deg/s for ``seconds``: the firmware ms at which ``stabilizer.yaw`` changed,
    and at each of those the jump of the yaw motor combination (m1 - m2 + m3 - m4) from that
    controller tick to the next."""
    thrust = v.hover_thrust()
    rows = []
    for i in range(round(seconds * 1000)):
        if i % 10 == 0:
            v.commander_rpyt(roll=0.0, pitch=0.0, yawrate=60.0, thrust=thrust)
        v.advance(0.001)
        m = v.motors_pwm
        rows.append((v.firmware_ms, v.read_log("stabilizer.yaw"), m[0] - m[1] + m[2] - m[3]))
    ms, yaw, motors = np.array(rows, dtype=float).T
    at = np.flatnonzero(np.diff(yaw) != 0)[:-1] + 1
    return ms[at].astype(int), np.abs(motors[at] - motors[at + 2])


@pytest.mark.parametrize("estimator", [1, 2])
def test_estimator_parameter_sets_when_the_attitude_changes(hovering, estimator):
    """``stabilizer.estimator = 2`` (Kalman): the attitude the controller sees changes at the
    estimator's 100 Hz, at instants that wander against the ms clock (the 50 Hz log's), and
    the unfiltered yaw D term makes each change a one-tick pulse of the yaw motor commands;
    ``pid_attitude.yaw_kd = 0`` removes it. 1 (complementary): every 500 Hz controller tick,
    no pulses."""
    hovering.write_param("stabilizer.estimator", estimator)
    fly(hovering, seconds=0.5)
    changes, jumps = _yawing(hovering, seconds=4.0)
    gaps = np.diff(changes)
    if estimator == 1:
        assert set(gaps) == {2}
    else:
        assert set(gaps) <= {8, 10, 12} and abs(gaps.mean() - 10.0) < 0.5
        assert len(set(changes % 20)) == 10      # at every phase of a 50 Hz log period
    assert (np.median(jumps) > 10_000) == (estimator == 2), np.median(jumps)  # 52 000 : 170
    hovering.write_param("pid_attitude.yaw_kd", 0.0)
    _, jumps = _yawing(hovering, seconds=1.0)
    assert np.median(jumps) < 2000          # gyro noise through the rate loop: about 340
