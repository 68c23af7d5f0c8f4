"""Emulated Crazyflie firmware: PID controller, legacy X mixer, RPYT commander, supervisor.

Faithful to the conventions of crazyflie-firmware (``pid.c``, ``attitude_pid_controller.c``,
``controller_pid.c``, ``power_distribution_quadrotor.c``, ``crtp_commander_rpyt.c``,
``commander.c``, ``supervisor.c``):

* The estimator's pitch is the *legacy* pitch ``theta_legacy = -theta`` (positive nose up), and the
  rate loop is fed ``(gyro.x, -gyro.y, gyro.z)``; the yaw output is negated before mixing.
* PID (``pid.c``): ``e = desired - measured``, ``u = kp e + ki sat(int e dt, i_limit)
  + kd de/dt``, both loops' derivatives unfiltered as the firmware's defaults leave them
  (``ATTITUDE_LPF_ENABLE`` and ``ATTITUDE_RATE_LPF_ENABLE`` false; with the Kalman estimator's
  100 Hz attitude steps the yaw D term gives one-tick pulses, see ``SimVehicle``); rate outputs
  saturate to ``+-32767``. The rate loop differentiates the gyro as the sensor task passes it on:
  low-passed at 80 Hz (the accelerometer at 30 Hz), :class:`ImuFilter`.
* Mixer: ``r = roll/2``, ``p = pitch/2``; ``m1 = T - r + p + y``, ``m2 = T - r - p - y``,
  ``m3 = T + r - p + y``, ``m4 = T + r + p - y``; if one exceeds 65535 all four are reduced by the
  excess, then each is clipped at 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

__all__ = [
    "RATE_LIMIT",
    "Commander",
    "ImuFilter",
    "Lpf2p",
    "Pid",
    "PidController",
    "Setpoint",
    "Supervisor",
    "battery_compensated_pwm",
    "mix_legacy_x",
]

RATE_LIMIT = 32767.0
"""Saturation of the rate-loop outputs (``INT16_MAX``)."""
MIN_THRUST = 1000
MAX_THRUST = 60000
WDT_LEVEL_OUT_MS = 500
WDT_SHUTDOWN_MS = 2000
IS_FLYING_HYSTERESIS_MS = 2000
FLIGHT_THRESHOLD_PWM = 1000
LANDING_TIMEOUT_MS = 3000
ESTOP_WATCHDOG_MS = 1000  # DEFAULT_EMERGENCY_STOP_WATCHDOG_TIMEOUT


class Lpf2p:
    """``lpf2p.c``: a 2nd-order Butterworth low-pass in direct form II at ``rate_hz``."""

    __slots__ = ("_a1", "_a2", "_b0", "_b1", "_b2", "_d1", "_d2")

    def __init__(self, *, cutoff_hz: float, rate_hz: float) -> None:
        ohm = math.tan(math.pi * cutoff_hz / rate_hz)
        c = 1.0 + 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm
        self._b0 = ohm * ohm / c
        self._b1 = 2.0 * self._b0
        self._b2 = self._b0
        self._a1 = 2.0 * (ohm * ohm - 1.0) / c
        self._a2 = (1.0 - 2.0 * math.cos(math.pi / 4.0) * ohm + ohm * ohm) / c
        self.reset()

    def reset(self, sample: float = 0.0) -> None:
        """``lpf2pReset``: the state of a filter that has seen ``sample`` forever."""
        self._d1 = self._d2 = sample / (self._b0 + self._b1 + self._b2)

    def apply(self, x: float) -> float:
        """One sample in, one filtered sample out."""
        d0 = x - self._d1 * self._a1 - self._d2 * self._a2
        y = d0 * self._b0 + self._d1 * self._b1 + self._d2 * self._b2
        self._d2, self._d1 = self._d1, d0
        return y


class ImuFilter:
    """The sensor task's low-pass filters (``sensors_bmi088_bmp388.c``): gyro at
    ``GYRO_LPF_CUTOFF_FREQ`` = 80 Hz, accelerometer at ``ACCEL_LPF_CUTOFF_FREQ`` = 30 Hz. The
    firmware runs them at the IMU's 1 kHz; here at ``rate_hz`` (the emulated firmware's 500 Hz).
    What the rate loop, the estimator and the ``gyro``/``acc`` logs see."""

    GYRO_CUTOFF_HZ: ClassVar[float] = 80.0
    ACC_CUTOFF_HZ: ClassVar[float] = 30.0

    def __init__(self, *, rate_hz: float) -> None:
        self._gyro = [Lpf2p(cutoff_hz=self.GYRO_CUTOFF_HZ, rate_hz=rate_hz) for _ in range(3)]
        self._acc = [Lpf2p(cutoff_hz=self.ACC_CUTOFF_HZ, rate_hz=rate_hz) for _ in range(3)]
        self._acc[2].reset(1.0)  # at rest: 1 g up, no start transient
        self.gx = self.gy = self.gz = self.ax = self.ay = 0.0
        self.az = 1.0

    def update(self, *, gx: float, gy: float, gz: float, ax: float, ay: float, az: float
               ) -> None:
        """One raw sample (deg/s, g) in; the filtered one in the attributes."""
        g, a = self._gyro, self._acc
        self.gx, self.gy, self.gz = g[0].apply(gx), g[1].apply(gy), g[2].apply(gz)
        self.ax, self.ay, self.az = a[0].apply(ax), a[1].apply(ay), a[2].apply(az)


class Pid:
    """One ``pid.c`` loop (units of the caller: deg and deg/s in, deg/s or PWM counts out)."""

    __slots__ = ("dt", "i_limit", "integ", "kd", "ki", "kp", "lpf", "out_limit", "prev_error")

    def __init__(self, *, kp: float, ki: float, kd: float, i_limit: float, out_limit: float,
                 dt: float, cutoff_hz: float) -> None:
        self.kp, self.ki, self.kd = kp, ki, kd
        self.i_limit, self.out_limit, self.dt = i_limit, out_limit, dt
        # pid.c's enableDFilter; 0 Hz: unfiltered
        self.lpf = Lpf2p(cutoff_hz=cutoff_hz, rate_hz=1.0 / dt) if cutoff_hz > 0.0 else None
        self.reset()

    @property
    def filtered(self) -> bool:
        return self.lpf is not None

    def reset(self) -> None:
        """``pidReset``: clear integral, previous error and the derivative filter."""
        self.integ = 0.0
        self.prev_error = 0.0
        if self.lpf is not None:
            self.lpf.reset()

    def update(self, error: float) -> float:
        """One update with ``error = desired - measured``; returns the (limited) output."""
        dt = self.dt
        deriv = (error - self.prev_error) / dt
        fd = deriv if self.lpf is None else self.lpf.apply(deriv)
        integ = self.integ + error * dt
        lim = self.i_limit
        if lim != 0.0:
            integ = lim if integ > lim else -lim if integ < -lim else integ
        self.integ = integ
        out = self.kp * error + self.kd * fd + self.ki * integ
        lim = self.out_limit
        if lim != 0.0:
            out = lim if out > lim else -lim if out < -lim else out
        self.prev_error = error
        return out


def _cap_angle(a: float) -> float:
    """``capAngle``: wrap degrees to [-180, 180)."""
    return (a + 180.0) % 360.0 - 180.0


class PidController:
    """``controller_pid.c`` in RPYT mode: attitude (deg) -> rate (deg/s) -> int16 outputs."""

    # name: (kp, ki, kd, i_limit), platform_defaults_cf2.h
    GAINS: ClassVar[dict[str, tuple[float, float, float, float]]] = {
        "roll_rate": (250.0, 500.0, 2.5, 33.3),
        "pitch_rate": (250.0, 500.0, 2.5, 33.3),
        "yaw_rate": (120.0, 16.7, 0.0, 166.7),
        "roll": (6.0, 3.0, 0.0, 20.0),
        "pitch": (6.0, 3.0, 0.0, 20.0),
        "yaw": (6.0, 1.0, 0.35, 360.0),
    }

    def __init__(self, *, dt: float = 1.0 / 500.0, yaw_max_delta_deg: float = 0.0) -> None:
        self.dt = dt
        self.yaw_max_delta_deg = yaw_max_delta_deg
        self.pids: dict[str, Pid] = {}
        for name, (kp, ki, kd, il) in self.GAINS.items():
            rate = name.endswith("_rate")
            self.pids[name] = Pid(kp=kp, ki=ki, kd=kd, i_limit=il,
                                  out_limit=RATE_LIMIT if rate else 0.0, dt=dt,
                                  cutoff_hz=0.0)
        self._ordered = tuple(self.pids[n] for n in ("roll", "pitch", "yaw", "roll_rate",
                                                       "pitch_rate", "yaw_rate"))
        self.reset(yaw_deg=0.0)

    def reset(self, *, yaw_deg: float) -> None:
        """``attitudeControllerResetAllPID`` and re-seed the integrated yaw setpoint."""
        for pid in self.pids.values():
            pid.reset()
        self.yaw_desired = yaw_deg
        self.roll_out = self.pitch_out = self.yaw_out = 0.0
        self.attitude_desired = (0.0, 0.0, yaw_deg)   # controller.roll/pitch/yaw, deg
        self.rate_desired = (0.0, 0.0, 0.0)            # controller.rollRate/..., deg/s

    def update(self, *, sp: Setpoint, roll: float, pitch_legacy: float, yaw: float,
               gx: float, gy: float, gz: float) -> tuple[float, float, float]:
        """One 500 Hz update; angles in deg (legacy pitch), gyro in deg/s (body, right-handed).

        Returns ``(control.roll, control.pitch, control.yaw)`` in int16 units, yaw already
        negated as ``controller_pid.c`` does.
        """
        yd = _cap_angle(self.yaw_desired + sp.yawrate * self.dt)
        ymd = self.yaw_max_delta_deg
        if ymd != 0.0:
            delta = _cap_angle(yd - yaw)
            if delta > ymd:
                yd = yaw + ymd
            elif delta < -ymd:
                yd = yaw - ymd
        self.yaw_desired = yd
        p = self._ordered
        rr = p[0].update(sp.roll - roll)
        pr = p[1].update(sp.pitch - pitch_legacy)
        ye = yd - yaw
        ye = ye - 360.0 if ye > 180.0 else ye + 360.0 if ye < -180.0 else ye
        yr = p[2].update(ye)
        self.attitude_desired = (sp.roll, sp.pitch, yd)
        self.rate_desired = (rr, pr, yr)
        self.roll_out = float(int(p[3].update(rr - gx)))
        self.pitch_out = float(int(p[4].update(pr + gy)))   # measured = -gyro.y
        self.yaw_out = -float(int(p[5].update(yr - gz)))
        return self.roll_out, self.pitch_out, self.yaw_out


def mix_legacy_x(*, thrust: float, roll: float, pitch: float,
                 yaw: float) -> tuple[int, int, int, int]:
    """Legacy X mixer with the "reduce all four" saturation rule; returns PWM m1..m4 (0..65535)."""
    r = int(roll / 2.0)
    p = int(pitch / 2.0)
    y = int(yaw)
    t = int(thrust)
    m1 = t - r + p + y
    m2 = t - r - p - y
    m3 = t + r - p + y
    m4 = t + r + p - y
    hi = max(m1, m2, m3, m4)
    red = hi - 65535 if hi > 65535 else 0
    return (max(m1 - red, 0), max(m2 - red, 0), max(m3 - red, 0), max(m4 - red, 0))


def battery_compensated_pwm(*, ithrust: float, vbat_v: float) -> int:
    """``motorsSetRatio`` with ``ENABLE_THRUST_BAT_COMPENSATED`` (``motors.c``, brushed motors).

    ``t = 60 ithrust / 65536``, ``u = -0.0006239 t^2 + 0.088 t`` (the motor voltage wanted, V),
    ``pwm = 65535 min(u / vbat, 1)``; below 2 V the battery reading is not trusted and ``ithrust``
    passes unchanged. Makes thrust independent of the battery until the cell is too low.
    """
    if vbat_v < 2.0:
        return int(ithrust)
    t = ithrust * (60.0 / 65536.0)
    ratio = (-0.0006239 * t * t + 0.088 * t) / vbat_v
    return int((ratio if ratio < 1.0 else 1.0) * 65535.0)


@dataclass(slots=True)
class Setpoint:
    """What the controller is asked for: deg, legacy pitch (nose up > 0), deg/s, PWM counts."""

    roll: float = 0.0
    pitch: float = 0.0
    yawrate: float = 0.0
    thrust: float = 0.0


class Commander:
    """``crtp_commander_rpyt.c`` decoding plus the ``commander.c`` setpoint watchdog."""

    def __init__(self) -> None:
        self.thrust_locked = True
        self.priority_disabled = True      # COMMANDER_PRIORITY_DISABLE at boot
        self.sp = Setpoint()
        self.timestamp_ms = 0

    def rpyt(self, *, roll: float, pitch: float, yawrate: float, thrust: int,
             now_ms: int) -> None:
        """Decode one legacy RPYT packet (values exactly as on the wire)."""
        if self.priority_disabled:
            self.thrust_locked = True
        if thrust == 0:
            self.thrust_locked = False
        t = 0 if (self.thrust_locked or thrust < MIN_THRUST) else min(thrust, MAX_THRUST)
        self.sp = Setpoint(roll=roll, pitch=pitch, yawrate=yawrate, thrust=float(t))
        self.timestamp_ms = now_ms
        self.priority_disabled = False

    def stop(self, *, now_ms: int) -> None:
        """The generic commander's stop setpoint: the null setpoint, motors off."""
        self.sp = Setpoint()
        self.timestamp_ms = now_ms
        self.priority_disabled = False

    def notify_stop(self, *, remain_valid_ms: int, now_ms: int) -> None:
        """``commanderNotifySetpointsStop``: the setpoint expires in ``remain_valid_ms``."""
        setback = min(WDT_SHUTDOWN_MS - remain_valid_ms, now_ms)
        self.timestamp_ms = now_ms - setback

    def age_ms(self, now_ms: int) -> int:
        """Milliseconds since the current setpoint was set."""
        return now_ms - self.timestamp_ms

    def current(self, *, now_ms: int) -> Setpoint:
        """The setpoint the stabilizer uses now, after the watchdog."""
        age = now_ms - self.timestamp_ms
        if age > WDT_SHUTDOWN_MS:
            self.sp = Setpoint()
        elif age > WDT_LEVEL_OUT_MS:
            self.priority_disabled = True
            sp = self.sp
            if sp.roll or sp.pitch or sp.yawrate:
                self.sp = Setpoint(thrust=sp.thrust)
        return self.sp


class Supervisor:
    """``supervisor.c`` and ``supervisor_state_machine.c``, reduced to what a user can observe:
    arming, flying, level-out, landed, lock.

    *Flying* holds while a motor ran above idle within the last 2 s
    (``IS_FLYING_HYSTERESIS_THRESHOLD``). From *Flying* a setpoint older than 0.5 s goes to
    *WarningLevelOut*, whose only ways out are a fresh setpoint (back to *Flying*) or one older
    than 2 s (*Locked*, until a restart): level-out has no way to *Landed*. So a commander that
    falls silent within 2 s of the motors' last run above idle locks the vehicle even after a
    stop setpoint; stop setpoints sent on until it reports landed (``supervisor.info`` bit 4
    clear) leave it *Landed*; 3 s later (``LANDING_TIMEOUT_MS``) it is reset and disarmed, and
    re-armed at once where it arms itself (*ReadyToFly*), else left *PreFlChecksPassed*.
    An emergency stop locks it, in *Landed* only at the landing timeout (:meth:`update`).
    """

    def __init__(self, *, auto_arm: bool = True) -> None:
        self.armed = self.auto_arm = auto_arm
        self.locked = False
        self.latest_thrust_ms = -1
        self.landed_ms = -1
        self.state = "ReadyToFly" if auto_arm else "PreFlChecksPassed"

    @property
    def is_flying(self) -> bool:
        """``supervisor.isFlying`` (bit 4 of ``supervisor.info``): Flying or WarningLevelOut."""
        return self.state in ("Flying", "WarningLevelOut")

    def update(self, *, now_ms: int, motor_sum: int, setpoint_age_ms: int,
               emergency_stop: bool = False) -> bool:
        """Update at 1 kHz; returns whether the motors may run. Sets ``locked`` on timeout and
        on an emergency stop (``stabilizer.stop``, a CRTP emergency stop or its watchdog): at
        once in every state but *Landed*, which has no transition for it
        (``supervisor_state_machine.c``): there at the landing timeout, when the reset leads
        through *PreFlChecksNotPassed* to *Locked*."""
        if self.locked:
            return False
        if emergency_stop and (self.state != "Landed"
                               or now_ms - self.landed_ms > LANDING_TIMEOUT_MS):
            self.locked, self.armed, self.state = True, False, "Locked"
            return False
        if motor_sum > FLIGHT_THRESHOLD_PWM:
            self.latest_thrust_ms = now_ms
        thrust_recent = (self.latest_thrust_ms >= 0
                         and now_ms - self.latest_thrust_ms < IS_FLYING_HYSTERESIS_MS)
        state = self.state
        if not self.armed:
            self.state = "PreFlChecksPassed"
            return False
        if state in ("Flying", "WarningLevelOut"):
            if setpoint_age_ms > WDT_SHUTDOWN_MS:  # locked, disarmed
                self.locked, self.armed = True, False
                self.state = "Locked"
                return False
            if setpoint_age_ms > WDT_LEVEL_OUT_MS:
                self.state = "WarningLevelOut"
            elif state == "WarningLevelOut":
                self.state = "Flying"
            elif not thrust_recent:
                self.state, self.landed_ms = "Landed", now_ms
        elif thrust_recent:
            self.state = "Flying"
        elif state != "Landed":
            self.state = "ReadyToFly"
        elif now_ms - self.landed_ms > LANDING_TIMEOUT_MS:  # reset: disarmed, auto-arm re-arms
            self.armed = self.auto_arm
            self.state = "ReadyToFly" if self.armed else "PreFlChecksPassed"
            return self.armed
        return True
