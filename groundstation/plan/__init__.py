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
:math:`x_j` the excitation signals of :mod:`groundstation.plan.excitation` (zero outside
excitation phases).
Errors read ``FILE:LINE: key.path: problem; what to change`` (see :mod:`groundstation.plan.toml`).
"""

from __future__ import annotations

import logging
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from groundstation.errors import PlanError
from groundstation.plan.altitude import AltitudeHoldConfig
from groundstation.plan.schedule import (
    MAX_RATE_RANGE_DEG_S,
    SETPOINT_CHANNELS,
    UNITS,
    Phase,
    Safety,
    Schedule,
    VehicleLimits,
)
from groundstation.plan.sections import (
    ExcitationSpec,
    PhaseSpec,
    check_thrust,
    read_altitude_hold,
    read_phase,
    read_safety,
    read_vehicle,
)
from groundstation.plan.settings import LiveIdConfig, read_live_id, read_parameters
from groundstation.plan.toml import TomlSource, TomlTable, did_you_mean, shown

__all__ = [
    "MAX_PLAN_S",
    "MAX_RATE_RANGE_DEG_S",
    "SETPOINT_CHANNELS",
    "SHIPPED_PLANS_DIR",
    "UNITS",
    "ExcitationSpec",
    "LiveIdConfig",
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

SHIPPED_PLANS_DIR = Path(__file__).resolve().parents[2] / "flightplans"
_NAME = re.compile(r"[A-Za-z0-9_-][A-Za-z0-9._-]{0,63}")
"""A plan name: it becomes part of the session file name, so no path separators, no leading dot,
at most 64 characters."""
MAX_PLAN_S = 3600.0
"""The longest plan, s: an hour, many batteries' worth (at 100 Hz, 360 000 setpoints); a plan
of thousands of long phases would otherwise compile into gigabytes of setpoints."""
_TOP_KEYS = (
    "name",
    "description",
    "setpoint_rate_hz",
    "hover_thrust",
    "vehicle",
    "safety",
    "altitude_hold",
    "live_id",
    "parameters",
    "phase",
)


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
    live_id: LiveIdConfig | None = None  # [live_id]: identify while flying (docs/live-id.md)
    parameters: tuple[tuple[str, float], ...] = ()  # [parameters]: ("group.name", value)

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
    raise PlanError(f"{name_or_path}: no such plan file; {did_you_mean(path.name, names)}"
                    f"give a path or one of {names}")


def load_plan(path: str | Path) -> Plan:
    """Read, validate and return the plan in ``path`` (or the shipped plan of that name)."""
    path = find_plan(path)
    if path.is_dir():
        raise PlanError(f"{path}: is a folder; give a plan file (.toml) or a shipped plan's "
                        "name, e.g. prbs-3axis")
    if not path.is_file():  # opening a FIFO waits for a writer; /dev/zero reads forever
        raise PlanError(f"{path}: not a regular file (a device, FIFO or socket); give a plan "
                        "file (.toml)")
    try:
        with path.open("rb") as fh:
            head = fh.read(len(_HDF5_SIGNATURE))
            raw = b"" if head == _HDF5_SIGNATURE else head + fh.read(MAX_PLAN_BYTES)
    except OSError as exc:
        raise PlanError(f"{path}: cannot read the plan ({exc.strerror or exc}); check the "
                        "file") from None
    if len(raw) > MAX_PLAN_BYTES:
        raise PlanError(f"{path}: larger than {MAX_PLAN_BYTES // 1024} KiB, so not a flight "
                        "plan (a plan is a few KiB of TOML)")
    try:
        # an editor's UTF-8 byte order mark (Notepad's) is no text: skipped, as TOML tools do
        text = raw.decode("utf-8-sig") if raw else None
    except UnicodeDecodeError:
        text = None
    if text is None and head:  # binary: say so, not which byte the UTF-8 decoder choked on
        what = ("it looks like an HDF5 file, a session or a model" if head == _HDF5_SIGNATURE
                else "not UTF-8 text")
        raise PlanError(f"{path}: not a TOML flight plan ({what}); give a plan file (.toml) or "
                        "a shipped plan's name, e.g. prbs-3axis")
    if path.suffix.lower() != ".toml":  # a CSV or JSON given as the plan: not "fix the syntax"
        try:
            tomllib.loads(text or "")
        except tomllib.TOMLDecodeError as exc:
            raise PlanError(f"{path}: not a TOML flight plan (a {path.suffix or 'suffix-less'} "
                            f"file that does not read as TOML: {str(exc).splitlines()[0]}); "
                            "give a plan file (.toml) or a shipped plan's name, e.g. "
                            "prbs-3axis") from None
    return parse_plan(text=text or "", source=str(path), name=path.stem)


#: Largest plan file read, bytes (the shipped plans are 2-5 KiB).
MAX_PLAN_BYTES = 1024 * 1024
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
"""The first bytes of an HDF5 file (session and model files)."""


#: Most parts of a dotted key or table header read (a plan's have 1-4): tomllib takes time
#: growing with the square of their number (a 100 kB key of 50 000 parts: minutes).
MAX_KEY_PARTS = 64
_KEY_PART = r"""(?:[A-Za-z0-9_-]+|"[^"\n]*"|'[^'\n]*')"""
_DEEP_KEY = re.compile(rf"(?:^|[{{,])[ \t]*\[{{0,2}}[ \t]*(?:{_KEY_PART}[ \t]*\.[ \t]*)"
                       rf"{{{MAX_KEY_PARTS},}}{_KEY_PART}[ \t]*[=\]]", re.MULTILINE)


def _plan_name(top: TomlTable, *, default: str) -> str:
    """``name`` (or ``default``, the file name) checked against :data:`_NAME`."""
    value = top.get("name", str, default=default)
    if _NAME.fullmatch(value):
        return value
    shown = repr(value) if len(value) <= 40 else f"{value[:37]!r}... ({len(value)} characters)"
    rule = (
        "1-64 characters from letters, digits, '-', '_', '.', not starting with '.' "
        "(it becomes part of the session file name)"
    )
    if "name" in top.data:
        raise top.src.error(("name",), f"{shown} is not a valid plan name; use {rule}")
    raise PlanError(
        f"{top.src.source}: the plan name defaults to the file name {shown}, which is not a "
        f"valid plan name; add name = \"...\" with {rule}, or rename the file"
    )


def parse_plan(*, text: str, source: str = "<plan>", name: str = "plan") -> Plan:
    """Validate TOML ``text``; ``source`` prefixes errors, ``name`` is the default plan name.
    A leading UTF-8 byte order mark is skipped (tomllib reads it as an invalid statement)."""
    text = text.removeprefix("\ufeff")
    deep = _DEEP_KEY.search(text)
    if deep is not None:  # tomllib's time grows with the square of a dotted key's parts
        line = text.count("\n", 0, deep.start()) + 1
        raise PlanError(f"{source}:{line}: invalid TOML: a dotted key or table header of more "
                        f"than {MAX_KEY_PARTS} parts; a plan's keys have a few")
    try:
        data = tomllib.loads(text)
    except ValueError as exc:  # TOMLDecodeError, or an integer of more than 4300 digits
        long = None if isinstance(exc, tomllib.TOMLDecodeError) else re.search(r"\d{4301,}", text)
        if long is not None:  # Python's own limit, worded for Python programmers: say it here
            line = text.count("\n", 0, long.start()) + 1
            raise PlanError(f"{source}:{line}: invalid TOML: a number of {len(long.group())} "
                            "digits; a plan's numbers have a few") from None
        msg = str(exc).splitlines()[0]
        pos = re.search(r"\(at line (\d+), column (\d+)\)", msg)
        at = f"{source}:{pos.group(1)}" if pos else source
        raise PlanError(f"{at}: invalid TOML: {msg}; fix the syntax on that line") from None
    except RecursionError:  # tomllib parses nested arrays and inline tables by recursion
        raise PlanError(f"{source}: invalid TOML: arrays or inline tables nested too deeply to "
                        "read; a plan nests them a few levels at most") from None
    if not data:  # else "vehicle: missing required key", as if one table were forgotten
        what = "is empty" if not text.strip() else "holds only comments and blank lines"
        raise PlanError(f"{source}: the file {what}: no keys or tables, so no plan; start from "
                        f"a shipped plan, e.g. copy {SHIPPED_PLANS_DIR / 'hover-check.toml'} "
                        "(schema: docs/flightplans.md)")
    src = TomlSource(text=text, source=source)
    top = TomlTable(src, (), data).allow(set(_TOP_KEYS))
    plan_name = _plan_name(top, default=name)
    rate = top.number("setpoint_rate_hz", lo=2.0, hi=100.0, unit="Hz", default=10.0)
    vehicle = read_vehicle(TomlTable(src, ("vehicle",), top.get("vehicle", dict)))
    hover = top.pwm("hover_thrust")
    check_thrust(src, path=("hover_thrust",), value=hover, vehicle=vehicle)
    safety = read_safety(
        TomlTable(src, ("safety",), top.get("safety", dict, default={})), vehicle=vehicle,
        rate_hz=rate,
    )
    hold = top.get("altitude_hold", dict, default=None)
    altitude_hold = (
        None if hold is None
        else read_altitude_hold(TomlTable(src, ("altitude_hold",), hold), vehicle=vehicle,
                                 hover_thrust=hover)
    )
    raw_live = top.get("live_id", dict, default=None)
    live_id = None if raw_live is None else read_live_id(TomlTable(src, ("live_id",), raw_live))
    raw_params = top.get("parameters", dict, default={})
    parameters = read_parameters(TomlTable(src, ("parameters",), raw_params))
    raw_phases = top.get("phase", list)
    if len(raw_phases) < 2:
        raise src.error(("phase",), "a plan needs a takeoff and a landing [[phase]]; add them")
    phases: list[PhaseSpec] = []
    ticks = 0
    for i, raw in enumerate(raw_phases):
        where = "first" if i == 0 else "last" if i == len(raw_phases) - 1 else "middle"
        phases.append(read_phase(TomlTable(src, ("phase", i), raw), where=where, vehicle=vehicle,
                                 hover_thrust=hover, rate_hz=rate))
        ticks += phases[-1].n_ticks
        if ticks > MAX_PLAN_S * rate + 1e-6:
            raise src.error(
                ("phase", i, "duration"),
                f"the phases up to this one last {ticks / rate:g} s, more than a plan may fly "
                f"({MAX_PLAN_S:g} s; a battery lasts minutes); shorten or remove phases",
            )
        named = [p.name for p in phases[:-1]]
        if phases[-1].name in named:
            raise src.error(
                ("phase", i, "name"),
                f"{shown(phases[-1].name)} is already the name of "
                f"phase[{named.index(phases[-1].name)}]; rename it",
            )
    plan = Plan(
        name=plan_name,
        text=text,
        source=source,
        description=top.get("description", str, default=""),
        setpoint_rate_hz=rate,
        hover_thrust=hover,
        vehicle=vehicle,
        safety=safety,
        phases=tuple(phases),
        altitude_hold=altitude_hold,
        live_id=live_id,
        parameters=parameters,
    )
    log.debug("plan %s: %d phases, %d setpoints", plan.name, len(phases), plan.n_setpoints)
    return plan
