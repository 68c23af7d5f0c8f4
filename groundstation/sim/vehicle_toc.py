"""The simulated Crazyflie's tables as cflib reads them: its log variables and their types, its
parameters (the read-only ones, their values at power-on), and where each log value comes from
in the vehicle's state (:func:`log_getters`).

The names and types are crazyflie-firmware's (and what the Crazyflie client reads: flight tab,
battery bar, supervisor, tuning tab); :class:`~groundstation.sim.vehicle.SimVehicle` exposes them
as its class attributes, and :mod:`groundstation.sim.crtp` serves them as the log and parameter
TOCs.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

__all__ = ["DECKS", "LOG_VARIABLES", "PARAMS", "PARAMS_READ_ONLY", "default_params",
           "log_getters"]

FIRMWARE_REVISION0 = 0x2024_0A00   # arbitrary but stable identifier of the emulated build

LOG_VARIABLES: dict[str, str] = {
    "acc.x": "float", "acc.y": "float", "acc.z": "float",
    "gyro.x": "float", "gyro.y": "float", "gyro.z": "float",
    "stabilizer.roll": "float", "stabilizer.pitch": "float", "stabilizer.yaw": "float",
    "stabilizer.thrust": "float",
    "motor.m1": "uint16_t", "motor.m2": "uint16_t", "motor.m3": "uint16_t",
    "motor.m4": "uint16_t",
    "pwm.m1_pwm": "uint32_t", "pwm.m2_pwm": "uint32_t", "pwm.m3_pwm": "uint32_t",
    "pwm.m4_pwm": "uint32_t",
    "pm.vbat": "float", "pm.vbatMV": "uint16_t", "pm.batteryLevel": "uint8_t",
    "controller.cmd_thrust": "float", "controller.cmd_roll": "float",
    "controller.cmd_pitch": "float", "controller.cmd_yaw": "float",
    "stateEstimate.x": "float", "stateEstimate.y": "float", "stateEstimate.z": "float",
    # What the Crazyflie client reads (flight tab, battery bar, supervisor, tuning tab):
    "stateEstimate.roll": "float", "stateEstimate.pitch": "float",
    "stateEstimate.yaw": "float",
    "controller.roll": "float", "controller.pitch": "float", "controller.yaw": "float",
    "controller.rollRate": "float", "controller.pitchRate": "float",
    "controller.yawRate": "float",
    "controller.r_roll": "float", "controller.r_pitch": "float", "controller.r_yaw": "float",
    "controller.accelz": "float", "controller.actuatorThrust": "float",
    "pm.state": "int8_t", "supervisor.info": "uint16_t",
    "sys.canfly": "uint8_t", "sys.isFlying": "uint8_t", "sys.isTumbled": "uint8_t",
}
DECKS = ("bcFlow", "bcFlow2", "bcLighthouse4", "bcLoco", "bcDWM1000", "bcZRanger2",
         "bcMultiranger", "bcAI", "bcLedRing", "bcUSD")
"""The ``deck`` parameter group (read-only, 1 = attached): no deck on the simulated vehicle."""

PARAMS: dict[str, str] = {
    **{f"{g}.{a}_{k}": "float" for g in ("pid_rate", "pid_attitude")
       for a in ("roll", "pitch", "yaw") for k in ("kp", "ki", "kd")},
    "stabilizer.estimator": "uint8_t",
    "stabilizer.controller": "uint8_t",
    "stabilizer.stop": "uint8_t",
    "commander.enHighLevel": "uint8_t",
    "pm.lowVoltage": "float",
    "pm.criticalLowVoltage": "float",
    "firmware.revision0": "uint32_t",
    "firmware.revision1": "uint16_t",
    "firmware.modified": "uint8_t",
    **{f"deck.{d}": "uint8_t" for d in DECKS},
}
PARAMS_READ_ONLY = frozenset({"firmware.revision0", "firmware.revision1", "firmware.modified",
                              *(f"deck.{d}" for d in DECKS)})


def default_params() -> dict[str, float]:
    """The values of the parameters the vehicle keeps itself (not the PID gains) at power-on."""
    return {
        "stabilizer.estimator": 1.0, "stabilizer.controller": 1.0, "stabilizer.stop": 0.0,
        "commander.enHighLevel": 0.0, "pm.lowVoltage": 3.2, "pm.criticalLowVoltage": 3.0,
        "firmware.revision0": float(FIRMWARE_REVISION0), "firmware.revision1": 0.0,
        "firmware.modified": 0.0, **{f"deck.{d}": 0.0 for d in DECKS},
    }


def log_getters(v: Any) -> dict[str, Callable[[], float]]:
    """Where each of :data:`LOG_VARIABLES` comes from in the state of ``v``, a
    :class:`~groundstation.sim.vehicle.SimVehicle` (its filtered IMU, body, attitude as the
    controller sees it, mixer inputs and outputs, battery and supervisor)."""
    s, b = v.imu, v.body
    g: dict[str, Callable[[], float]] = {
        "acc.x": lambda: s.ax, "acc.y": lambda: s.ay, "acc.z": lambda: s.az,
        "gyro.x": lambda: s.gx, "gyro.y": lambda: s.gy, "gyro.z": lambda: s.gz,
        "stabilizer.roll": lambda: v._att[0], "stabilizer.pitch": lambda: v._att[1],
        "stabilizer.yaw": lambda: v._att[2],
        "stabilizer.thrust": lambda: v._control[0],
        "pm.vbat": lambda: v.battery.voltage_v,
        "pm.vbatMV": lambda: float(round(1000.0 * v.battery.voltage_v)),
        "pm.batteryLevel": lambda: float(round(100.0 * v.battery.charge)),
        "controller.cmd_thrust": lambda: v._control[0],
        "controller.cmd_roll": lambda: v._control[1],
        "controller.cmd_pitch": lambda: v._control[2],
        "controller.cmd_yaw": lambda: v._control[3],
        "stateEstimate.x": lambda: b.x, "stateEstimate.y": lambda: b.y,
        "stateEstimate.z": lambda: b.z,
    }
    ctrl = v.controller
    for i, axis in enumerate(("roll", "pitch", "yaw")):
        g[f"stateEstimate.{axis}"] = lambda i=i: v._att[i] * (-1.0 if i == 1 else 1.0)
        g[f"controller.{axis}"] = lambda i=i: ctrl.attitude_desired[i]
        g[f"controller.{axis}Rate"] = lambda i=i: ctrl.rate_desired[i]
    g["controller.r_roll"] = lambda: s.gx
    g["controller.r_pitch"] = lambda: -s.gy
    g["controller.r_yaw"] = lambda: s.gz
    g["controller.accelz"] = lambda: s.az
    g["controller.actuatorThrust"] = lambda: v._control[0]
    g["pm.state"] = lambda: 3.0 if v.low_power else 0.0   # 0 battery, 3 low power
    g["supervisor.info"] = lambda: float(v.supervisor_info())
    g["sys.canfly"] = lambda: float(v.supervisor.armed and not v.supervisor.locked)
    g["sys.isFlying"] = lambda: float(v.supervisor.is_flying)
    g["sys.isTumbled"] = lambda: 0.0
    for i in range(4):
        g[f"motor.m{i + 1}"] = lambda i=i: float(v._pwm[i])
        g[f"pwm.m{i + 1}_pwm"] = lambda i=i: float(v._duty_pwm[i])
    return g
