"""Declarative flight plans: the TOML schema, validation that names key and line, the Schedule.

A plan file (``flightplans/*.toml``, schema in ``docs/flightplans.md``) is parsed with
:mod:`tomllib`, validated against the schema and the plan's own ``[vehicle]`` limits (values
outside them are refused, never clamped) and compiled by :meth:`Plan.compile` into a
:class:`Schedule`: one setpoint per tick :math:`t_k = k / f_s` (:math:`f_s` =
``setpoint_rate_hz``), which the flight runner streams with
``Commander.send_setpoint(roll, pitch, yaw_rate, thrust)``.

Setpoint :math:`k` in phase :math:`i` (ticks :math:`[s_i, e_i)`, :math:`j = k - s_i`,
:math:`m_i = e_i - s_i`):

.. math::  \\text{thrust}_k = T_0 + (T_1 - T_0)\\,\\tfrac{j}{m_i - 1} + x^{\\text{thrust}}_j,
           \\qquad \\text{roll}_k = x^{\\text{roll}}_j \\;(\\text{likewise pitch, yaw rate}),

with the ramp :math:`T_0 \\to T_1` of take-off and landing phases (constant otherwise) and
:math:`x_j` the excitation signals of :mod:`sysid.excitation` (zero outside excitation phases).
Errors read ``FILE:LINE: key.path: problem; what to change`` (see :mod:`groundstation.plan_toml`).
"""

from __future__ import annotations

import logging
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.altitude import AltitudeHoldConfig
from groundstation.errors import PlanError
from groundstation.plan_toml import TomlSource, TomlTable
from groundstation.schedule import (
    SETPOINT_CHANNELS,
    UNITS,
    Phase,
    Safety,
    Schedule,
    VehicleLimits,
)
from sysid import excitation as ex

__all__ = [
    "SETPOINT_CHANNELS",
    "SHIPPED_PLANS_DIR",
    "UNITS",
    "ExcitationSpec",
    "Phase",
    "PhaseSpec",
    "Plan",
    "Safety",
    "Schedule",
    "VehicleLimits",
    "find_plan",
    "load_plan",
    "parse_plan",
]

log = logging.getLogger(__name__)

SHIPPED_PLANS_DIR = Path(__file__).resolve().parent.parent / "flightplans"
KINDS = ("takeoff", "hover", "excitation", "landing")
SIGNALS = ("prbs", "doublet", "step", "chirp")
_SIGNAL_KEYS = {
    "prbs": {"register_length", "period", "clock_period", "seed"},
    "doublet": {"width", "start"},
    "step": {"start"},
    "chirp": {"f_start_hz", "f_end_hz", "sweep"},
}
_TOP_KEYS = (
    "name",
    "description",
    "setpoint_rate_hz",
    "hover_thrust",
    "vehicle",
    "safety",
    "altitude_hold",
    "phase",
)
_PHASE_KEYS = {
    "takeoff": {"thrust_start", "thrust_end"},
    "landing": {"thrust_start", "thrust_end"},
    "hover": {"thrust"},
    "excitation": set(SETPOINT_CHANNELS),
}
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


@dataclass(frozen=True)
class Plan:
    """A validated flight plan; ``text`` is the file's full source, kept for the session file."""

    name: str
    text: str
    source: str
    description: str
    setpoint_rate_hz: float
    hover_thrust: int
    vehicle: VehicleLimits
    safety: Safety
    phases: tuple[PhaseSpec, ...]
    altitude_hold: AltitudeHoldConfig | None = None

    @property
    def n_setpoints(self) -> int:
        return sum(p.n_ticks for p in self.phases)

    @property
    def duration(self) -> float:
        """Seconds from the first setpoint to the end of the last setpoint period."""
        return self.n_setpoints / self.setpoint_rate_hz

    def compile(self) -> Schedule:
        """The setpoint arrays, one per tick (see the module docstring for the equation)."""
        n = self.n_setpoints
        axes = {a: np.zeros(n) for a in SETPOINT_CHANNELS}
        phase_id = np.zeros(n, dtype=np.int64)
        phases, k0 = [], 0
        for pid, spec in enumerate(self.phases):
            m, seg = spec.n_ticks, slice(k0, k0 + spec.n_ticks)
            ramp = np.arange(m) / (m - 1) if m > 1 else np.ones(m)
            axes["thrust"][seg] = spec.thrust_start + (spec.thrust_end - spec.thrust_start) * ramp
            for exc in spec.excitation:
                axes[exc.axis][seg] += exc.samples(n_ticks=m, rate_hz=self.setpoint_rate_hz)
            phase_id[seg] = pid
            phases.append(
                Phase(
                    id=pid,
                    name=spec.name,
                    kind=spec.kind,
                    start_tick=k0,
                    end_tick=k0 + m,
                    rate_hz=self.setpoint_rate_hz,
                )
            )
            k0 += m
        thrust = np.rint(axes["thrust"]).astype(np.int64)
        return Schedule(
            name=self.name,
            rate_hz=self.setpoint_rate_hz,
            roll=axes["roll"],
            pitch=axes["pitch"],
            yaw_rate=axes["yaw_rate"],
            thrust=thrust,
            phase_id=phase_id,
            phases=tuple(phases),
            vehicle=self.vehicle,
            safety=self.safety,
            altitude_hold=self.altitude_hold,
        )


def find_plan(name_or_path: str | Path) -> Path:
    """A plan file path: the path itself if it exists, else a shipped plan of that name."""
    path = Path(name_or_path)
    if path.exists():
        return path
    shipped = SHIPPED_PLANS_DIR / f"{path.name}.toml"
    if path.suffix == "" and len(path.parts) == 1 and shipped.exists():
        return shipped
    names = sorted(p.stem for p in SHIPPED_PLANS_DIR.glob("*.toml"))
    raise PlanError(f"{name_or_path}: no such plan file; give a path or one of {names}")


def load_plan(path: str | Path) -> Plan:
    """Read, validate and return the plan in ``path`` (or the shipped plan of that name)."""
    path = find_plan(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise PlanError(f"{path}: cannot read the plan ({exc}); check the file") from None
    return parse_plan(text=text, source=str(path), name=path.stem)


def parse_plan(*, text: str, source: str = "<plan>", name: str = "plan") -> Plan:
    """Validate TOML ``text``; ``source`` prefixes errors, ``name`` is the default plan name."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        msg = str(exc).splitlines()[0]
        pos = re.search(r"\(at line (\d+), column (\d+)\)", msg)
        at = f"{source}:{pos.group(1)}" if pos else source
        raise PlanError(f"{at}: invalid TOML: {msg}; fix the syntax on that line") from None
    src = TomlSource(text=text, source=source)
    top = TomlTable(src, (), data).allow(set(_TOP_KEYS))
    rate = top.number("setpoint_rate_hz", lo=2.0, hi=100.0, unit="Hz", default=10.0)
    vehicle = _read_vehicle(TomlTable(src, ("vehicle",), top.get("vehicle", dict)))
    hover = top.pwm("hover_thrust")
    _check_thrust(src, ("hover_thrust",), hover, vehicle)
    safety = _read_safety(
        TomlTable(src, ("safety",), top.get("safety", dict, default={})), vehicle, rate
    )
    hold = top.get("altitude_hold", dict, default=None)
    altitude_hold = (
        None if hold is None
        else _read_altitude_hold(TomlTable(src, ("altitude_hold",), hold), vehicle, hover)
    )
    raw_phases = top.get("phase", list)
    if len(raw_phases) < 2:
        raise src.error(("phase",), "a plan needs a takeoff and a landing [[phase]]; add them")
    phases: list[PhaseSpec] = []
    for i, raw in enumerate(raw_phases):
        where = "first" if i == 0 else "last" if i == len(raw_phases) - 1 else "middle"
        phases.append(_read_phase(TomlTable(src, ("phase", i), raw), where, vehicle, hover, rate))
        named = [p.name for p in phases[:-1]]
        if phases[-1].name in named:
            raise src.error(
                ("phase", i, "name"),
                f"'{phases[-1].name}' is already the name of "
                f"phase[{named.index(phases[-1].name)}]; rename it",
            )
    plan = Plan(
        name=top.get("name", str, default=name),
        text=text,
        source=source,
        description=top.get("description", str, default=""),
        setpoint_rate_hz=rate,
        hover_thrust=hover,
        vehicle=vehicle,
        safety=safety,
        phases=tuple(phases),
        altitude_hold=altitude_hold,
    )
    log.debug("plan %s: %d phases, %d setpoints", plan.name, len(phases), plan.n_setpoints)
    return plan


def _read_vehicle(t: TomlTable) -> VehicleLimits:
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
    )


def _check_thrust(
    src: TomlSource, path: tuple, value: float, v: VehicleLimits, what: str = "thrust"
) -> None:
    """Refuse a thrust outside ``[thrust_min, thrust_max]``, naming the key, value and limit."""
    key = "thrust_min" if value < v.thrust_min else "thrust_max" if value > v.thrust_max else ""
    if key:
        raise src.error(
            path,
            f"{what} = {value:g} PWM, beyond {src.ref(('vehicle', key))} = "
            f"{getattr(v, key)} PWM; change the value or the limit",
        )


def _read_safety(t: TomlTable, v: VehicleLimits, rate: float) -> Safety:
    t.allow({"on_abort", "descent_duration", "descent_thrust", "max_rate_deg_s"})
    max_rate = t.get("max_rate_deg_s", float, default=None, unit="deg/s")
    if max_rate is not None:
        max_rate = t.number("max_rate_deg_s", lo=10.0, hi=5000.0, unit="deg/s")
    if t.choice("on_abort", ("descend", "stop"), default="stop") == "stop":
        return Safety(max_rate_deg_s=max_rate)
    ticks = t.ticks("descent_duration", rate_hz=rate, hi=10.0)
    thrust = t.pwm("descent_thrust")
    _check_thrust(t.src, ("safety", "descent_thrust"), thrust, v)
    return Safety(on_abort="descend", descent_duration=ticks / rate, descent_thrust=thrust,
                  max_rate_deg_s=max_rate)


def _read_altitude_hold(t: TomlTable, v: VehicleLimits, hover: int) -> AltitudeHoldConfig:
    """``[altitude_hold]``: every key optional (defaults in :class:`AltitudeHoldConfig`)."""
    d = AltitudeHoldConfig()
    t.allow(set(AltitudeHoldConfig.__dataclass_fields__))
    kinds = tuple(t.get("kinds", list, default=list(d.kinds)))
    bad = [k for k in kinds if k not in ("hover", "excitation")]
    if bad or not kinds:
        raise t.src.error((*t.path, "kinds"), f"{bad or kinds} must be a non-empty list of "
                          "'hover' and 'excitation'; take-off and landing follow the plan")
    variable = t.get("variable", str, default=d.variable)
    if "." not in variable:
        raise t.src.error((*t.path, "variable"), f"'{variable}' is not a log variable "
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
    for value in (hover + cfg.max_trim, hover - cfg.max_trim):
        _check_thrust(t.src, (*t.path, "max_trim"), value, v,
                      what=f"hover_thrust {hover} ± max_trim {cfg.max_trim}")
    return cfg


def _read_phase(t: TomlTable, where: str, v: VehicleLimits, hover: int, rate: float) -> PhaseSpec:
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
    n_ticks = t.ticks("duration", rate_hz=rate)
    if kind in ("takeoff", "landing"):
        low, up = v.thrust_min, kind == "takeoff"
        t0 = t.pwm("thrust_start", default=low if up else hover)
        t1 = t.pwm("thrust_end", default=hover if up else low)
    else:
        t0 = t1 = t.pwm("thrust", default=hover) if kind == "hover" else hover
    for key, value in (("thrust_start", t0), ("thrust_end", t1), ("thrust", t0)):
        if key in t.data and kind != "excitation":
            _check_thrust(t.src, (*t.path, key), value, v)
    axes = [a for a in SETPOINT_CHANNELS if kind == "excitation" and a in t.data]
    if kind == "excitation" and not axes:
        raise t.src.error(
            t.path,
            "an excitation phase needs at least one of roll, pitch, "
            "yaw_rate, thrust tables, e.g. [phase.roll]",
        )
    excitation = tuple(
        _read_signal(TomlTable(t.src, (*t.path, a), t.data[a]), v, hover, rate, n_ticks)
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


def _read_signal(
    t: TomlTable, v: VehicleLimits, hover: int, rate: float, n_ticks: int
) -> ExcitationSpec:
    axis, signal = t.path[-1], t.choice("signal", SIGNALS)
    t.allow({"signal", "amplitude"} | _SIGNAL_KEYS[signal])
    unit, at = UNITS[axis], (*t.path, "amplitude")
    amplitude = t.number("amplitude", lo=-65535, hi=65535, unit=unit)
    symmetric = signal in ("prbs", "chirp")
    if amplitude == 0 or (amplitude < 0 and symmetric):
        raise t.src.error(at, f"{amplitude:g} {unit} must be {'> 0' if symmetric else '!= 0'}")
    if axis in _AXIS_LIMIT:
        limit = getattr(v, _AXIS_LIMIT[axis])
        if abs(amplitude) > limit:
            raise t.src.error(
                at,
                f"±{abs(amplitude):g} {unit} exceeds "
                f"{t.src.ref(('vehicle', _AXIS_LIMIT[axis]))} = {limit:g} {unit}; "
                "lower the amplitude or raise the limit",
            )
    else:
        reach = (amplitude,) if signal == "step" else (abs(amplitude), -abs(amplitude))
        for value in reach:
            _check_thrust(t.src, at, hover + value, v, what=f"hover_thrust {hover} {value:+g}")
    spec: dict[str, Any] = {"axis": axis, "signal": signal, "amplitude": amplitude}
    if signal == "prbs":
        spec.update(_read_prbs(t, n_ticks))
    elif signal in ("doublet", "step"):
        start = spec["start"] = t.ticks("start", rate_hz=rate, default=0.0, lo_open=False)
        width = spec["width"] = t.ticks("width", rate_hz=rate) if signal == "doublet" else 0
        if start + 2 * width > n_ticks or start >= n_ticks:
            raise t.src.error(
                (*t.path, "width" if width else "start"),
                f"start{' + 2 x width' if width else ''} = "
                f"{(start + 2 * width) / rate:g} s does not fit in the phase "
                f"({n_ticks / rate:g} s); shorten it or lengthen the phase",
            )
    else:
        nyquist = rate / 2
        spec["sweep"] = t.choice("sweep", ("linear", "log"), default="linear")
        for key in ("f_start_hz", "f_end_hz"):
            f = spec[key] = t.number(key, lo=0, hi=nyquist, unit="Hz")
            if f == nyquist or (spec["sweep"] == "log" and f == 0):
                raise t.src.error(
                    (*t.path, key),
                    f"{f:g} Hz must be > 0 for a log sweep and "
                    f"< {nyquist:g} Hz (Nyquist of the setpoint rate)",
                )
    return ExcitationSpec(**spec)


def _read_prbs(t: TomlTable, n_ticks: int) -> dict[str, int]:
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
