"""SimVehicle: a simulated Crazyflie 2.1 (physics at 1 kHz plus emulated firmware).

This is the object the CRTP side (``groundstation/sim/crtp.py``) drives. Everything it exposes is
what the real vehicle exposes on the wire: log variables, parameters (their tables and where each
log value comes from: :mod:`groundstation.sim.vehicle_toc`), console text, commander input. Sign
conventions are the firmware's (see docs/simulator.md): ``stabilizer.pitch`` is the legacy pitch,
positive nose up; ``gyro`` is right-handed in the body frame (x forward, y left, z up); a wire
pitch of ``-10`` (what ``cflib`` sends for ``send_setpoint(pitch=+10)``) tilts the nose down, so
``stabilizer.pitch`` settles at ``-10`` and ``gyro.y`` is positive while it tilts.
"""

from __future__ import annotations

import dataclasses
import logging
import random
from typing import ClassVar

from groundstation.errors import GroundStationError
from groundstation.sim.firmware import (
    ESTOP_WATCHDOG_MS,
    Commander,
    ImuFilter,
    PidController,
    Supervisor,
    battery_compensated_pwm,
    mix_legacy_x,
)
from groundstation.sim.physics import (
    GRAVITY_M_S2,
    Battery,
    RigidBody,
    VehicleConstants,
    motor_thrust_n,
)
from groundstation.sim.sensors import NoiseModel, Sensors
from groundstation.sim.vehicle_toc import (
    DECKS,
    LOG_VARIABLES,
    PARAMS,
    PARAMS_READ_ONLY,
    default_params,
    log_getters,
)

__all__ = ["SimConfigError", "SimVehicle"]

log = logging.getLogger(__name__)

_DT_S = 0.001          # physics / stabilizer tick
_PID_DT_S = 0.002      # attitude and rate loops, 500 Hz
PM_LOW_TIMEOUT_S = 5.0  # DEFAULT_BAT_LOW_DURATION_TO_TRIGGER_SEC (platform_defaults_cf2.h)
_KALMAN_PERIOD_MS = 10  # estimator_kalman.c PREDICT_RATE 100 Hz
_KALMAN = 2             # stabilizer.estimator: 1 complementary, 2 Kalman


class SimConfigError(GroundStationError, ValueError):
    """A simulator option is unknown or out of range."""


def _noise_value(name: str, v: object) -> object:
    """A noise override: biases are one number; levels one number (all axes) or three."""
    if "bias" in name:
        return float(v)  # type: ignore[arg-type]
    if isinstance(v, int | float):
        return (float(v),) * 3
    return tuple(float(x) for x in v)  # type: ignore[union-attr]


class SimVehicle:
    """A simulated Crazyflie 2.1: rigid-body physics at 1 kHz + emulated firmware (PID, mixer,
    commander, supervisor, sensors). Deterministic for a given seed. Not thread-safe: the owner
    (the CRTP side) calls it from one thread only.

    ``overrides`` set fields of :class:`~groundstation.sim.physics.VehicleConstants` (e.g.
    ``mass_kg=0.030``), of :class:`~groundstation.sim.sensors.NoiseModel` (e.g.
    ``gyro_vib_dps=0``), ``auto_arm`` (default True, as on a CF2.1) or ``start_z_m`` (start at rest
    in the air at this height with the motors spinning at hover thrust, as if released from a
    hand; for hover tests. Send setpoints at once or the motors spin down).

    The estimator is the parameter ``stabilizer.estimator``, as on the firmware. ``1``
    (complementary, the default) gives the controller the true attitude at every 500 Hz tick.
    ``2`` (Kalman) changes the attitude only when the estimator predicts, every 10 ms
    (``PREDICT_RATE``), at instants that wander by a controller tick against the firmware's
    ms clock (the logs' clock); the attitude D term (``pid_attitude.yaw_kd``, unfiltered as in
    the firmware) turns each step into a one-tick pulse of the motor commands, which a 50 Hz log
    samples at random: the aliasing ``groundstation.plan.aliasing`` detects (docs/simulator.md).
    """

    LOG_VARIABLES: ClassVar[dict[str, str]] = LOG_VARIABLES
    DECKS = DECKS  # the ``deck`` parameter group: no deck attached
    PARAMS: ClassVar[dict[str, str]] = PARAMS
    PARAMS_READ_ONLY = PARAMS_READ_ONLY

    def __init__(self, *, seed: int = 0, vbat_full: float = 4.15, **overrides: float) -> None:
        const_fields = {f.name for f in dataclasses.fields(VehicleConstants)}
        noise_fields = {f.name for f in dataclasses.fields(NoiseModel)}
        auto_arm = bool(overrides.pop("auto_arm", True))
        start_z_m = float(overrides.pop("start_z_m", 0.0))
        unknown = sorted(set(overrides) - const_fields - noise_fields)
        if unknown:
            raise SimConfigError(
                f"unknown simulator option(s) {unknown}; choose from "
                f"{sorted(const_fields | noise_fields | {'auto_arm', 'start_z_m'})}")
        if not 3.0 < vbat_full <= 4.25:
            raise SimConfigError(f"vbat_full={vbat_full} V is not a LiPo voltage; use 3.0..4.25 V")
        self.const = VehicleConstants(**{k: float(v) for k, v in overrides.items()
                                         if k in const_fields})
        noise = NoiseModel(**{k: _noise_value(k, v) for k, v in overrides.items()
                              if k in noise_fields})
        self._rng = random.Random(seed)
        self.body = RigidBody(c=self.const)
        self.battery = Battery(full_v=vbat_full, c=self.const)
        self.sensors = Sensors(rng=self._rng, noise=noise, rate_hz=1.0 / _PID_DT_S)
        self.imu = ImuFilter(rate_hz=1.0 / _PID_DT_S)  # what the firmware's sensor task passes on
        self.controller = PidController(dt=_PID_DT_S)
        self.commander = Commander()
        self.supervisor = Supervisor(auto_arm=auto_arm)
        self._auto_arm = auto_arm
        self._tick = 0
        self._pwm = (0, 0, 0, 0)               # mixer outputs (motor.m1..m4)
        self._duty_pwm = (0, 0, 0, 0)          # after battery compensation (pwm.m1_pwm..)
        self._targets = (0.0, 0.0, 0.0, 0.0)
        self._control = (0.0, 0.0, 0.0, 0.0)   # thrust, roll, pitch, yaw (mixer inputs)
        self._att = (0.0, 0.0, 0.0)             # roll, legacy pitch, yaw, deg
        self._predict_ms = 0                    # the Kalman estimator's next prediction
        self._predict_rng = random.Random(seed ^ 0x6B616C6D)  # its timing, apart from the noise
        self._stop_param = False         # stabilizer.stop (a parameter: set back to 0, gone)
        self._stop_requested = False     # a CRTP emergency stop: until a restart
        self._stop_watchdog_ms = -1      # the emergency-stop watchdog's last notification
        self._low_s = 0.0                # seconds the battery has been below pm.lowVoltage
        self.stop_count = 0              # stops: stop setpoints and the supervisor's locks
        self.stop_setpoints = 0          # stop setpoints received (the ground station's)
        self._console: list[str] = [
            "SYS: ----------------------------\n",
            "SYS: Crazyflie 2.1 (simulated by groundstation.sim) is up and running!\n",
        ]
        if start_z_m > 0.0:   # released from a hand with the motors at hover thrust
            b = self.body
            b.z, b.on_ground = start_z_m, False
            b.f1 = b.f2 = b.f3 = b.f4 = self.const.mass_kg * GRAVITY_M_S2 / 4.0
            self._targets = (b.f1, b.f2, b.f3, b.f4)
        self._params: dict[str, float] = default_params()
        self._log_getters = log_getters(self)

    # ----------------------------------------------------------------- time
    @property
    def time_s(self) -> float:
        """Simulation time since power-on, seconds."""
        return self._tick * _DT_S

    @property
    def firmware_ms(self) -> int:
        """Firmware tick in ms (what log packets carry)."""
        return self._tick

    def advance(self, dt_s: float) -> None:
        """Step the 1 kHz loop by ``round(dt_s * 1000)`` ms."""
        body_step = self.body.step
        fw = self._firmware_tick
        tick = self._tick
        for _ in range(round(dt_s * 1000.0)):
            tick += 1
            self._tick = tick
            if not tick & 1:
                fw(tick)
            t1, t2, t3, t4 = self._targets
            body_step(t1, t2, t3, t4, _DT_S)

    def _firmware_tick(self, now: int) -> None:
        """The 500 Hz part: sensors, estimator, commander, supervisor, controller, mixer."""
        body, sensors = self.body, self.sensors
        pwm = self._pwm
        out = self._duty_pwm
        sensors.sample(body=body, duty=(out[0] + out[1] + out[2] + out[3]) / 262140.0)
        imu = self.imu
        imu.update(gx=sensors.gx, gy=sensors.gy, gz=sensors.gz, ax=sensors.ax, ay=sensors.ay,
                   az=sensors.az)
        if self._params["stabilizer.estimator"] != _KALMAN:
            roll, pitch, yaw = body.euler_deg()
            self._att = (roll, -pitch, yaw)                  # legacy CF2 pitch convention
        elif now >= self._predict_ms:
            roll, pitch, yaw = body.euler_deg()
            self._att = (roll, -pitch, yaw)
            # The next prediction 10 ms on, give or take a controller tick: a random walk of
            # its phase against the ms clock, mean period 10 ms.
            self._predict_ms = now + _KALMAN_PERIOD_MS + self._predict_rng.choice((-2, 0, 0, 2))
        roll, pitch, yaw = self._att
        cmd = self.commander
        sp = cmd.current(now_ms=now)
        sup = self.supervisor
        was_locked = sup.locked
        estop = self._emergency_stop(now)
        may_run = sup.update(now_ms=now, motor_sum=pwm[0] + pwm[1] + pwm[2] + pwm[3],
                             setpoint_age_ms=cmd.age_ms(now), emergency_stop=estop)
        if sup.locked and not was_locked:
            self.stop_count += 1
            why = "an emergency stop" if estop else "setpoint timeout"
            self._console.append(f"SUPERVISOR: Locked due to {why}, reboot required\n")
        ctrl = self.controller
        thrust = sp.thrust
        if thrust == 0.0:
            ctrl.reset(yaw_deg=yaw)
            self._control = (0.0, 0.0, 0.0, 0.0)
        else:
            r, p, y = ctrl.update(sp=sp, roll=roll, pitch_legacy=pitch, yaw=yaw,
                                  gx=imu.gx, gy=imu.gy, gz=imu.gz)
            self._control = (thrust, r, p, y)
        if may_run and not estop and thrust != 0.0:
            t, r, p, y = self._control
            pwm = mix_legacy_x(thrust=t, roll=r, pitch=p, yaw=y)
        else:
            pwm = (0, 0, 0, 0)
        self._pwm = pwm
        vbat = self.battery.voltage_v
        bc = battery_compensated_pwm
        out = (bc(ithrust=pwm[0], vbat_v=vbat) if pwm[0] else 0,
               bc(ithrust=pwm[1], vbat_v=vbat) if pwm[1] else 0,
               bc(ithrust=pwm[2], vbat_v=vbat) if pwm[2] else 0,
               bc(ithrust=pwm[3], vbat_v=vbat) if pwm[3] else 0)
        self._duty_pwm = out
        duties = (out[0] / 65535.0, out[1] / 65535.0, out[2] / 65535.0, out[3] / 65535.0)
        vbat = self.battery.update(duties=duties, dt_s=_PID_DT_S)
        c = self.const
        self._targets = (motor_thrust_n(pwm=out[0], vbat_v=vbat, c=c),
                         motor_thrust_n(pwm=out[1], vbat_v=vbat, c=c),
                         motor_thrust_n(pwm=out[2], vbat_v=vbat, c=c),
                         motor_thrust_n(pwm=out[3], vbat_v=vbat, c=c))
        # the firmware's power management (pm_stm32f4.c): low power once the battery has been
        # below pm.lowVoltage for PM_LOW_TIMEOUT_S without a break, flying or not; back to
        # "battery" when it recovers (at rest after landing)
        was_low = self.low_power
        self._low_s = self._low_s + _PID_DT_S if vbat < self._params["pm.lowVoltage"] else 0.0
        if self.low_power and not was_low:
            self._console.append(f"PM: Battery low ({vbat:.2f} V)\n")

    @property
    def low_power(self) -> bool:
        """``pm.state`` is lowPower (3): the battery below ``pm.lowVoltage`` for
        :data:`PM_LOW_TIMEOUT_S`, as the firmware's power management decides it."""
        return self._low_s > PM_LOW_TIMEOUT_S

    # ----------------------------------------------------------------- commander
    def commander_rpyt(self, *, roll: float, pitch: float, yawrate: float, thrust: int) -> None:
        """A legacy RPYT setpoint exactly as decoded from the wire (``<fffH``)."""
        self.commander.rpyt(roll=roll, pitch=pitch, yawrate=yawrate, thrust=int(thrust),
                            now_ms=self._tick)

    def commander_stop(self) -> None:
        """The stop setpoint: motors off."""
        self.commander.stop(now_ms=self._tick)
        self.stop_count += 1
        self.stop_setpoints += 1

    def commander_notify_stop(self, *, remain_valid_ms: int) -> None:
        """Hand priority back; the last setpoint stays valid for ``remain_valid_ms``."""
        self.commander.notify_stop(remain_valid_ms=int(remain_valid_ms), now_ms=self._tick)

    def emergency_stop(self) -> None:
        """A CRTP emergency stop (cflib ``supervisor.send_emergency_stop``, or the legacy
        localization packet): the firmware keeps the request until restarted, so the
        supervisor locks the vehicle (``crtp_localization_service.c``, ``supervisor.c``)."""
        self._stop_requested = True

    def emergency_stop_watchdog(self) -> None:
        """A notification of the emergency-stop watchdog: once one came, a gap of more than
        1 s (``DEFAULT_EMERGENCY_STOP_WATCHDOG_TIMEOUT``) is an emergency stop."""
        self._stop_watchdog_ms = self._tick

    def _emergency_stop(self, now_ms: int) -> bool:
        """``SUPERVISOR_CB_EMERGENCY_STOP`` at ``now_ms``."""
        return self._stop_param or self._stop_requested or (
            self._stop_watchdog_ms >= 0 and now_ms >= self._stop_watchdog_ms + ESTOP_WATCHDOG_MS)

    def arm(self, *, armed: bool) -> None:
        """Supervisor arming request (a CF2.1 is armed from power-on)."""
        if not self.supervisor.locked:
            self.supervisor.armed = bool(armed)

    # ----------------------------------------------------------------- log, params, console
    def supervisor_info(self) -> int:
        """``supervisor.info`` (``supervisor.c`` ``updateLogData``): bit 0 can be armed (state
        PreFlChecksPassed only), 1 armed, 2 auto-arm, 3 can fly, 4 flying (Flying or
        WarningLevelOut), 6 locked."""
        sup = self.supervisor
        can_fly = sup.armed and not sup.locked
        return ((sup.state == "PreFlChecksPassed") | sup.armed << 1 | self._auto_arm << 2
                | can_fly << 3 | sup.is_flying << 4 | sup.locked << 6)

    def read_log(self, name: str) -> float:
        """Current value of log variable ``name`` (units as in the firmware: g, deg/s, deg, V)."""
        try:
            return self._log_getters[name]()
        except KeyError:
            raise KeyError(f"no log variable {name!r}; see SimVehicle.LOG_VARIABLES") from None

    def read_param(self, name: str) -> float:
        """Current value of parameter ``name``."""
        group, _, field = name.partition(".")
        if group in ("pid_rate", "pid_attitude"):
            pid = self._pid_for(name)
            return getattr(pid, field.rsplit("_", 1)[1])
        try:
            return self._params[name]
        except KeyError:
            raise KeyError(f"no parameter {name!r}; see SimVehicle.PARAMS") from None

    def write_param(self, name: str, value: float) -> None:
        """Set parameter ``name``; PID gains and ``stabilizer.stop`` change the behaviour."""
        if name in self.PARAMS_READ_ONLY:
            log.warning("parameter %s is read-only; write ignored", name)
            return
        group, _, field = name.partition(".")
        if group in ("pid_rate", "pid_attitude"):
            setattr(self._pid_for(name), field.rsplit("_", 1)[1], float(value))
            return
        if name not in self._params:
            raise KeyError(f"no parameter {name!r}; see SimVehicle.PARAMS")
        if self.PARAMS[name].startswith(("uint", "int")):
            value = float(int(value))
        self._params[name] = float(value)
        if name == "stabilizer.stop":
            self._stop_param = bool(value)

    def _pid_for(self, name: str):
        if name not in self.PARAMS:
            raise KeyError(f"no parameter {name!r}; see SimVehicle.PARAMS")
        group, _, field = name.partition(".")
        axis = field.rsplit("_", 1)[0]
        return self.controller.pids[f"{axis}_rate" if group == "pid_rate" else axis]

    def drain_console(self) -> list[str]:
        """Console lines printed since the last call."""
        out, self._console = self._console, []
        return out

    # ----------------------------------------------------------------- read-only state
    @property
    def is_flying(self) -> bool:
        """The supervisor's is-flying flag (``supervisor.isFlying``: state Flying or
        WarningLevelOut, :class:`~groundstation.sim.firmware.Supervisor`)."""
        return self.supervisor.is_flying

    @property
    def is_locked(self) -> bool:
        """True once the watchdog has stopped the motors in flight; only a new vehicle unlocks."""
        return self.supervisor.locked

    @property
    def supervisor_state(self) -> str:
        """Supervisor state name as in ``supervisor.c`` (e.g. ``ReadyToFly``, ``Flying``)."""
        return self.supervisor.state

    @property
    def motors_pwm(self) -> tuple[int, int, int, int]:
        """Motor commands m1..m4 (0..65535) as logged by ``motor.m1..m4``: the mixer output.

        The duty actually applied after battery compensation is logged as ``pwm.m1_pwm..``.
        """
        return self._pwm

    @property
    def position_m(self) -> tuple[float, float, float]:
        """Position in the world frame (z up, origin at the take-off point), m."""
        b = self.body
        return (b.x, b.y, b.z)

    @property
    def attitude_deg(self) -> tuple[float, float, float]:
        """(roll, pitch, yaw) in deg as logged by ``stabilizer.*`` (legacy pitch: nose up > 0)."""
        return self._att

    @property
    def velocity_m_s(self) -> tuple[float, float, float]:
        """Velocity in the world frame, m/s."""
        b = self.body
        return (b.vx, b.vy, b.vz)

    @property
    def duty_mean(self) -> float:
        """Mean motor duty cycle (0..1) after battery compensation."""
        return sum(self._duty_pwm) / 262140.0

    def hover_thrust(self) -> int:
        """Thrust command (1000..60000) that carries the weight with level attitude.

        With battery compensation the motor voltage depends on the command only, so this does not
        change as the battery sags (until the compensation saturates near 3.3 V at hover).
        """
        c = self.const
        weight = c.mass_kg * GRAVITY_M_S2 / 4.0
        lo, hi = 0.0, 65535.0
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            pwm = battery_compensated_pwm(ithrust=mid, vbat_v=4.0)
            if motor_thrust_n(pwm=pwm, vbat_v=4.0, c=c) < weight:
                lo = mid
            else:
                hi = mid
        return round(0.5 * (lo + hi))
