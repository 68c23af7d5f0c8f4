"""The values a Crazyflie parameter of each C type can take, and the types of the firmware's
parameters a flight-test plan sets, so a ``[parameters]`` value the firmware cannot hold is
refused when the plan loads (``plan check``, and ``fly`` before connecting) instead of failing
in cflib's ``struct.pack`` after take-off checks.

:data:`CTYPES` mirrors cflib's ``ParamTocElement.types`` (the TOC's type names and the struct
codes cflib packs a written value with). :data:`KNOWN_TYPES` holds crazyflie-firmware's
writable attitude, rate, position and velocity controller, flight-mode, stabilizer, commander,
power-management and power-distribution parameters, as the pinned firmware's TOC names them
(``tests/sitl/test_param_types.py`` checks them against it). A name outside it is checked only
after connecting, against the type the firmware's TOC gives
(:func:`groundstation.flight.params.check_parameters`, with :func:`value_problem`), which has
the last word for every name.
"""

from __future__ import annotations

import math
import struct

__all__ = ["CTYPES", "KNOWN_TYPES", "type_range", "value_problem"]

CTYPES: dict[str, str] = {
    "int8_t": "<b", "int16_t": "<h", "int32_t": "<i", "int64_t": "<q",
    "uint8_t": "<B", "uint16_t": "<H", "uint32_t": "<I", "uint64_t": "<Q",
    "FP16": "<e", "float": "<f", "double": "<d",
}
"""TOC type name -> the struct code cflib packs a written value with."""

_FLOAT_MAX = {"FP16": 65504.0, "float": 3.4028234663852886e38, "double": 1.7976931348623157e308}

_PID_AXES = ("roll", "pitch", "yaw")
KNOWN_TYPES: dict[str, str] = {
    **{f"{g}.{a}_{k}": "float" for g in ("pid_rate", "pid_attitude") for a in _PID_AXES
       for k in ("kp", "ki", "kd", "kff")},
    "pid_rate.rateFiltEn": "int8_t",
    **{f"pid_rate.om{a}FiltCut": "float" for a in "xyz"},
    "pid_attitude.attFiltEn": "int8_t",
    "pid_attitude.attFiltCut": "float",
    "pid_attitude.yawMaxDelta": "float",
    **{f"posCtlPid.{a}{k}": "float" for a in "xyz" for k in ("Kp", "Ki", "Kd", "Kff")},
    **{f"posCtlPid.{k}": "float" for k in ("rLimit", "pLimit", "xVelMax", "yVelMax", "zVelMax")},
    "posCtlPid.thrustBase": "uint16_t",
    "posCtlPid.thrustMin": "uint16_t",
    **{f"velCtlPid.v{a}{k}": "float" for a in "xyz" for k in ("Kp", "Ki", "Kd", "KFF")},
    "stabilizer.estimator": "uint8_t",
    "stabilizer.controller": "uint8_t",
    "stabilizer.stop": "uint8_t",
    "commander.enHighLevel": "uint8_t",
    **{f"flightmode.{k}": "uint8_t" for k in ("althold", "poshold", "posSet", "yawMode",
                                              "stabModeRoll", "stabModePitch", "stabModeYaw")},
    "pm.lowVoltage": "float",
    "pm.criticalLowVoltage": "float",
    "powerDist.idleThrust": "uint32_t",
    "supervisor.landedTimeout": "uint16_t",
}
"""``group.name`` -> TOC type of crazyflie-firmware's parameters (all writable)."""


def type_range(ctype: str) -> tuple[float, float]:
    """The smallest and largest value a parameter of ``ctype`` holds (``KeyError`` for a type
    not in :data:`CTYPES`)."""
    code = CTYPES[ctype]
    if ctype in _FLOAT_MAX:
        return -_FLOAT_MAX[ctype], _FLOAT_MAX[ctype]
    bits = 8 * struct.calcsize(code)
    if code[-1].isupper():
        return 0, 2**bits - 1
    return -(2 ** (bits - 1)), 2 ** (bits - 1) - 1


def _show(value: float) -> str:
    return str(int(value)) if float(value).is_integer() and abs(value) < 1e15 else repr(value)


def value_problem(value: float, ctype: str) -> str:
    """``""`` when a parameter of TOC type ``ctype`` can take ``value`` (cflib packs it as the
    firmware holds it), else what is wrong in a few words, e.g. ``"300 is outside uint8_t's
    range 0 to 255"`` or ``"1.5 is not an integer (uint8_t, 0 to 255)"``. A type cflib does not
    name is left to cflib (``""``)."""
    if ctype not in CTYPES:
        return ""
    lo, hi = type_range(ctype)
    span = f"±{hi:.8g}" if ctype in _FLOAT_MAX else f"{_show(lo)} to {_show(hi)}"
    if not math.isfinite(value):
        return f"{value} is not a finite number ({ctype}, {span})"
    if ctype in _FLOAT_MAX:
        try:  # the float rounded to the type's precision may still overflow: ask struct
            struct.pack(CTYPES[ctype], float(value))
        except (OverflowError, struct.error):
            return f"{_show(value)} is outside {ctype}'s range {span}"
        return ""
    if not float(value).is_integer():
        return f"{_show(value)} is not an integer ({ctype}, {span})"
    if not lo <= int(value) <= hi:
        return f"{_show(value)} is outside {ctype}'s range {span}"
    return ""
