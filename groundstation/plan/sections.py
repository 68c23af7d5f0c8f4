"""The plan file's sections: how each TOML table is read, checked and turned into specs.

Used by :func:`groundstation.plan.parse_plan`. The flight's own tables are here (vehicle, safety,
altitude hold, phases and their excitation); what runs alongside the flight, ``[live_id]`` and
``[parameters]``, is read by :mod:`groundstation.plan.settings`. Every reader takes a
:class:`TomlTable` (so its errors name the key and its line) and refuses values outside the
plan's ``[vehicle]`` limits instead of clamping them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any

import numpy as np

import groundstation.plan.excitation as ex
from groundstation.plan.altitude import AltitudeHoldConfig
from groundstation.plan.schedule import (
    BATTERY_FLIGHT_S,
    MAX_RATE_RANGE_DEG_S,
    SETPOINT_CHANNELS,
    UNITS,
    Safety,
    VehicleLimits,
)
from groundstation.plan.toml import TomlSource, TomlTable, shown

__all__ = [
    "KINDS",
    "SIGNALS",
    "ExcitationSpec",
    "PhaseSpec",
    "check_thrust",
    "read_altitude_hold",
    "read_phase",
    "read_safety",
    "read_vehicle",
]

KINDS = ("takeoff", "hover", "excitation", "landing")
SIGNALS = ("prbs", "doublet", "step", "chirp")
_SIGNAL_KEYS = {
    "prbs": {"register_length", "period", "clock_period", "seed"},
    "doublet": {"width", "start"},
    "step": {"start"},
    "chirp": {"f_start_hz", "f_end_hz", "sweep"},
}
_PHASE_KEYS = {
    "takeoff": {"thrust_start", "thrust_end"},
    "landing": {"thrust_start", "thrust_end"},
    "hover": {"thrust"},
    "excitation": set(SETPOINT_CHANNELS),
}
_LOG_VARIABLE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\.[A-Za-z_][A-Za-z0-9_]*")
"""A firmware log variable, ``group.name`` (C identifiers)."""
_AXIS_LIMIT = {"roll": "max_roll_deg", "pitch": "max_pitch_deg", "yaw_rate": "max_yaw_rate_deg_s"}


@dataclass(frozen=True)
class ExcitationSpec:
    """One axis of an excitation phase; times in ticks, amplitude in the axis unit."""

    axis: str
    signal: str
    amplitude: float
    register_length: int = 0
    clock_period: int = 1  # ticks per PRBS chip
    seed: int = 1
    width: int = 0  # doublet half width, ticks
    start: int = 0  # ticks from phase start
    f_start_hz: float = 0.0
    f_end_hz: float = 0.0
    sweep: str = "linear"

    def samples(self, *, n_ticks: int, rate_hz: float) -> np.ndarray:
        """The signal over ``n_ticks`` setpoints, shape ``(n_ticks,)``."""
        n, amp = n_ticks, self.amplitude
        if self.signal == "prbs":
            return ex.prbs(
                n_samples=n,
                register_length=self.register_length,
                amplitude=amp,
                clock_period=self.clock_period,
                seed=self.seed,
            )
        if self.signal == "doublet":
            return ex.doublet(n_samples=n, width=self.width, amplitude=amp, start=self.start)
        if self.signal == "step":
            return ex.step(n_samples=n, amplitude=amp, start=self.start)
        return ex.chirp(
            n_samples=n,
            dt=1.0 / rate_hz,
            f_start=self.f_start_hz,
            f_end=self.f_end_hz,
            amplitude=amp,
            sweep=self.sweep,
        )

    def prbs_figures(self, *, n_ticks: int) -> dict[str, int | float]:
        """Period (chips, ticks), persistence-of-excitation order (ticks), periods covered."""
        period = ex.prbs_period(
            register_length=self.register_length, clock_period=self.clock_period
        )
        return {
            "register_length": self.register_length,
            "period_chips": (1 << self.register_length) - 1,
            "period_ticks": period,
            "clock_period_ticks": self.clock_period,
            "pe_order_ticks": ex.prbs_persistence_order(
                register_length=self.register_length, clock_period=self.clock_period
            ),
            "periods_covered": n_ticks / period,
            "seed": self.seed,
        }


@dataclass(frozen=True)
class PhaseSpec:
    """One ``[[phase]]``: thrust ramps from ``thrust_start`` to ``thrust_end`` (PWM)."""

    name: str
    kind: str
    n_ticks: int
    thrust_start: int
    thrust_end: int
    excitation: tuple[ExcitationSpec, ...] = ()


def read_vehicle(t: TomlTable) -> VehicleLimits:
    t.allow(set(VehicleLimits.__dataclass_fields__))
    thrust_min = t.pwm("thrust_min")
    thrust_max = t.number("thrust_max", lo=thrust_min, hi=65535, unit="PWM", kind=int, lo_open=True)
    return VehicleLimits(
        max_roll_deg=t.number("max_roll_deg", lo=0, hi=90, unit="deg", lo_open=True),
        max_pitch_deg=t.number("max_pitch_deg", lo=0, hi=90, unit="deg", lo_open=True),
        max_yaw_rate_deg_s=t.number(
            "max_yaw_rate_deg_s", lo=0, hi=2000, unit="deg/s", lo_open=True
        ),
        thrust_min=thrust_min,
        thrust_max=thrust_max,
        min_vbat=t.number("min_vbat", lo=3.0, hi=4.2, unit="V"),
        flight_time_s=t.number("flight_time_s", lo=0, hi=3600, unit="s", lo_open=True,
                               default=BATTERY_FLIGHT_S),
    )


def check_thrust(
    src: TomlSource, *, path: tuple, value: float, vehicle: VehicleLimits, what: str = "thrust"
) -> None:
    """Refuse a thrust outside ``[thrust_min, thrust_max]``, naming the key, value and limit
    (written so that a nan is refused too)."""
    key = "" if vehicle.thrust_min <= value <= vehicle.thrust_max else (
        "thrust_max" if value > vehicle.thrust_min else "thrust_min"
    )
    if key:
        raise src.error(
            path,
            f"{what} = {value:g} PWM, beyond {src.ref(('vehicle', key))} = "
            f"{getattr(vehicle, key)} PWM; change the value or the limit",
        )


def _hover(src: TomlSource, hover_thrust: int) -> str:
    """``hover_thrust 58000 (line 7)``: the other term of a sum checked against the limits
    (the error is on the line of the term it is raised for)."""
    line = src.line(("hover_thrust",))
    return f"hover_thrust {hover_thrust}" + (f" (line {line})" if line else "")


def read_safety(t: TomlTable, *, vehicle: VehicleLimits, rate_hz: float) -> Safety:
    t.allow({"on_abort", "descent_duration", "descent_thrust", "max_rate_deg_s"})
    max_rate = t.get("max_rate_deg_s", float, default=None, unit="deg/s")
    if max_rate is not None:
        lo, hi = MAX_RATE_RANGE_DEG_S
        max_rate = t.number("max_rate_deg_s", lo=lo, hi=hi, unit="deg/s")
    if t.choice("on_abort", ("descend", "stop"), default="stop") == "stop":
        return Safety(max_rate_deg_s=max_rate)
    ticks = t.ticks("descent_duration", rate_hz=rate_hz, hi=10.0)
    thrust = t.pwm("descent_thrust")
    check_thrust(t.src, path=("safety", "descent_thrust"), value=thrust, vehicle=vehicle)
    return Safety(on_abort="descend", descent_duration=ticks / rate_hz, descent_thrust=thrust,
                  max_rate_deg_s=max_rate)


def read_altitude_hold(t: TomlTable, *, vehicle: VehicleLimits, hover_thrust: int
                       ) -> AltitudeHoldConfig:
    """``[altitude_hold]``: every key optional (defaults in :class:`AltitudeHoldConfig`)."""
    d = AltitudeHoldConfig()
    t.allow(set(AltitudeHoldConfig.__dataclass_fields__))
    raw = t.data.get("kinds", list(d.kinds))
    bad = [k for k in raw if k not in ("hover", "excitation")] if isinstance(raw, list) else raw
    if bad or not raw:
        raise t.src.error((*t.path, "kinds"), f"{shown(bad or raw)} is not a valid value: kinds "
                          'must be a non-empty list of phase kinds from "hover" and "excitation", '
                          'e.g. ["hover"]; take-off and landing follow the plan')
    kinds = tuple(raw)
    variable = t.get("variable", str, default=d.variable)
    if not _LOG_VARIABLE.fullmatch(variable):
        raise t.src.error((*t.path, "variable"), f"{shown(variable)} is not a log variable "
                          "'group.name', e.g. 'stateEstimate.z'")
    cfg = AltitudeHoldConfig(
        variable=variable,
        target_m=t.number("target_m", lo=0.2, hi=5.0, unit="m", default=d.target_m),
        kp=t.number("kp", lo=0, hi=1e5, unit="PWM/m", default=d.kp),
        ki=t.number("ki", lo=0, hi=1e5, unit="PWM/(m s)", default=d.ki),
        kd=t.number("kd", lo=0, hi=1e5, unit="PWM/(m/s)", default=d.kd),
        max_trim=t.number("max_trim", lo=0, hi=30000, unit="PWM", kind=int, default=d.max_trim),
        kinds=kinds,
    )
    for value in (hover_thrust + cfg.max_trim, hover_thrust - cfg.max_trim):
        check_thrust(t.src, path=(*t.path, "max_trim"), value=value, vehicle=vehicle,
                     what=f"{_hover(t.src, hover_thrust)} ± max_trim {cfg.max_trim}")
    return cfg


def read_phase(t: TomlTable, *, where: str, vehicle: VehicleLimits, hover_thrust: int,
               rate_hz: float) -> PhaseSpec:
    kind = t.choice("kind", KINDS)
    expected = {"first": "takeoff", "last": "landing"}.get(where)
    if kind != (expected or kind) or (expected is None and kind in ("takeoff", "landing")):
        rule = (
            f"the {where} phase must be '{expected}'"
            if expected
            else ("takeoff/landing may only be the first/last phase")
        )
        raise t.src.error((*t.path, "kind"), f"'{kind}' here: {rule}; reorder the phases")
    t.allow({"name", "kind", "duration"} | _PHASE_KEYS[kind])
    n_ticks = t.ticks("duration", rate_hz=rate_hz)
    if kind in ("takeoff", "landing"):
        low, up = vehicle.thrust_min, kind == "takeoff"
        t0 = t.pwm("thrust_start", default=low if up else hover_thrust)
        t1 = t.pwm("thrust_end", default=hover_thrust if up else low)
    else:
        t0 = t1 = t.pwm("thrust", default=hover_thrust) if kind == "hover" else hover_thrust
    for key, value in (("thrust_start", t0), ("thrust_end", t1), ("thrust", t0)):
        if key in t.data and kind != "excitation":
            check_thrust(t.src, path=(*t.path, key), value=value, vehicle=vehicle)
    axes = [a for a in SETPOINT_CHANNELS if kind == "excitation" and a in t.data]
    if kind == "excitation" and not axes:
        raise t.src.error(
            t.path,
            "an excitation phase needs at least one of roll, pitch, "
            "yaw_rate, thrust tables, e.g. [phase.roll]",
        )
    excitation = tuple(
        read_signal(TomlTable(t.src, (*t.path, a), t.data[a]), vehicle=vehicle,
                    hover_thrust=hover_thrust, rate_hz=rate_hz, n_ticks=n_ticks)
        for a in axes
    )
    return PhaseSpec(
        name=t.get("name", str, default=kind),
        kind=kind,
        n_ticks=n_ticks,
        thrust_start=t0,
        thrust_end=t1,
        excitation=excitation,
    )


def read_signal(
    t: TomlTable, *, vehicle: VehicleLimits, hover_thrust: int, rate_hz: float, n_ticks: int
) -> ExcitationSpec:
    axis, signal = t.path[-1], t.choice("signal", SIGNALS)
    t.allow({"signal", "amplitude"} | _SIGNAL_KEYS[signal])
    unit, at = UNITS[axis], (*t.path, "amplitude")
    amplitude = t.number("amplitude", lo=-65535, hi=65535, unit=unit)
    symmetric = signal in ("prbs", "chirp")
    if amplitude == 0:
        raise t.src.error(at, f"0 {unit} excites nothing; give the {signal}'s size in {unit}"
                          f"{', > 0' if symmetric else ' (negative: the other way first)'}")
    if amplitude < 0 and symmetric:
        label = "PRBS" if signal == "prbs" else "chirp"
        raise t.src.error(at, f"{amplitude:g} {unit} must be > 0: a {label} is symmetric "
                          f"(±amplitude); give the magnitude, amplitude = {-amplitude:g}")
    if axis in _AXIS_LIMIT:
        limit = getattr(vehicle, _AXIS_LIMIT[axis])
        if not abs(amplitude) <= limit:  # not `>`: refuse a nan too
            raise t.src.error(
                at,
                f"±{abs(amplitude):g} {unit} exceeds "
                f"{t.src.ref(('vehicle', _AXIS_LIMIT[axis]))} = {limit:g} {unit}; "
                "lower the amplitude or raise the limit",
            )
    else:
        reach = (amplitude,) if signal == "step" else (abs(amplitude), -abs(amplitude))
        for value in reach:
            check_thrust(t.src, path=at, value=hover_thrust + value, vehicle=vehicle,
                         what=f"{_hover(t.src, hover_thrust)} {value:+g}")
    spec: dict[str, Any] = {"axis": axis, "signal": signal, "amplitude": amplitude}
    if signal == "prbs":
        spec.update(read_prbs(t, n_ticks=n_ticks))
    elif signal in ("doublet", "step"):
        start = spec["start"] = t.ticks("start", rate_hz=rate_hz, default=0.0, lo_open=False)
        width = spec["width"] = t.ticks("width", rate_hz=rate_hz) if signal == "doublet" else 0
        if start + 2 * width > n_ticks or start >= n_ticks:
            raise t.src.error(
                (*t.path, "width" if width else "start"),
                f"start{' + 2 x width' if width else ''} = "
                f"{(start + 2 * width) / rate_hz:g} s does not fit in the phase "
                f"({n_ticks / rate_hz:g} s); shorten it or lengthen the phase",
            )
    else:
        nyquist = rate_hz / 2
        spec["sweep"] = t.choice("sweep", ("linear", "log"), default="linear")
        log_sweep = spec["sweep"] == "log"
        for key in ("f_start_hz", "f_end_hz"):
            f = spec[key] = t.get(key, float, unit="Hz")
            # one check, one message: the bounds it states are the ones it applies
            if not (0 < f < nyquist if log_sweep else 0 <= f < nyquist):
                low = "> 0 Hz (a log sweep cannot start or end at 0)" if log_sweep else ">= 0 Hz"
                raise t.src.error(
                    (*t.path, key),
                    f"{f:g} Hz is out of range for a {spec['sweep']} sweep; use a value {low} "
                    f"and < {nyquist:g} Hz (Nyquist of the setpoint rate {rate_hz:g} Hz)",
                )
        if log_sweep and spec["f_start_hz"] == spec["f_end_hz"]:
            raise t.src.error(
                (*t.path, "f_end_hz"),
                f"a log sweep from {spec['f_start_hz']:g} to {spec['f_end_hz']:g} Hz has no "
                'ratio to sweep; use another f_end_hz, or sweep = "linear" for a sine',
            )
    return ExcitationSpec(**spec)


def read_prbs(t: TomlTable, *, n_ticks: int) -> dict[str, int]:
    if ("register_length" in t.data) == ("period" in t.data):
        raise t.src.error(
            t.path, "a PRBS needs exactly one of register_length (2-24) or period (2^n - 1 chips)"
        )
    if "period" in t.data:
        period = t.number("period", lo=3, hi=(1 << 24) - 1, unit="chips", kind=int)
        try:
            n = ex.register_length_for_period(period)
        except ex.ExcitationError as exc:
            raise t.src.error((*t.path, "period"), str(exc)) from None
    else:
        n = t.number(
            "register_length", lo=min(ex.LFSR_TAPS), hi=max(ex.LFSR_TAPS), unit="bits", kind=int
        )
    clock = t.number("clock_period", lo=1, hi=n_ticks, unit="ticks", kind=int, default=1)
    seed = t.number("seed", lo=1, hi=(1 << n) - 1, unit="(register state)", kind=int, default=1)
    return {"register_length": n, "clock_period": clock, "seed": seed}
