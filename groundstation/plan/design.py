"""The next flight's excitation, designed from an identified model (``groundstation plan design``).

Numbers in, plan text out: :class:`~groundstation.plan.model_facts.ModelFacts` holds what the
design needs from a model (poles, ``dt``, channel names, singular values, horizons, fits per
output), so this module loads no identification code; the command reads the model file (with
``sysid``'s hardened loader, inside the function) and hands the numbers over.
:func:`design_plan` edits the ``--from`` plan's text with
:func:`~groundstation.plan.toml.set_keys` (tomlkit: its comments and layout kept, every changed
value with a ``# design:`` comment saying why) and parses the result again, so the plan written
is the plan checked. The rules, with their equations, are in ``docs/flightplans.md``
("Designing the next flight"):

* PRBS chip :math:`T_{sw} \\le 2.78\\,\\tau_L / \\alpha_s` and period
  :math:`N T_{sw} \\ge 2\\pi \\beta_s \\tau_H` (Rivera and Jun 2000): :math:`\\tau_L = 1 / |s|`
  of the fastest mode below the setpoints' Nyquist frequency,
  :math:`\\tau_H = 1 / |\\mathrm{Re}\\,s|` of the slowest that settles within
  the phase (:math:`s = \\ln z / dt`), in whole setpoint ticks, the period at most the phase;
  the chip lengthened beyond the flown one only by a model that explains every excited axis
  well (:func:`~.model_facts.chip_doubt`: a model missing the fast modes over-estimates
  :math:`\\tau_L`);
* amplitude :math:`a = \\min(a_0 (1 + w), 0.9\\,L)` (never below :math:`a_0`, never beyond the
  limit :math:`L`), :math:`w` the axis' weakness from its fit and the singular values; never
  raised when the flown excitation already drove the model's inputs (the motors) to their
  limits in more than 1 % of its samples (:func:`~.model_facts.saturated`): more amplitude
  would be clipped, a nonlinearity no linear model explains. The motors' range is then shared
  out instead: an axis explained better than the worst gets
  :math:`a = a_0 (1 - 0.5 (w_{worst} - w))`, the worst keeps :math:`a_0`;
* seeds as far along the m-sequence from every flown start as the axes' spacing allows;
* an axis whose logged motor combination is aliased in the flown sessions (more than 5 % of
  its power in the top third of the band, with the firmware's attitude D term on that axis:
  :mod:`groundstation.plan.aliasing`) flies with that D term at 0 (``[parameters]``, restored
  after the flight).
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from groundstation.errors import PlanError
from groundstation.plan import Plan, parse_plan
from groundstation.plan.aliasing import d_term_changes
from groundstation.plan.excitation import prbs_shift
from groundstation.plan.model_facts import (
    AXIS_OUTPUTS,
    ModelFacts,
    axis_fit,
    chip_doubt,
    saturated,
    sv_weakness,
    weakness,
)
from groundstation.plan.timing import prbs_timing
from groundstation.plan.toml import comment_text, dotted, ensure_tables, key_lines, set_keys
from groundstation.plan.variants import advanced_seed

__all__ = ["AXIS_OUTPUTS", "MAX_SATURATION", "Change", "Design", "ModelFacts", "choose_seeds",
           "design_notes", "design_plan", "prbs_timing", "saturated", "weakness"]

_LIMIT = {"roll": "max_roll_deg", "pitch": "max_pitch_deg", "yaw_rate": "max_yaw_rate_deg_s"}
LIMIT_SHARE = 0.9  # amplitudes at most 0.9 x the vehicle limit (and at most 2x: weakness <= 1)
MAX_SATURATION = 0.01  # inputs at their limits in more of the flown excitation: no raise
HEADROOM = 0.5  # clipped: an axis w less weak than the weakest is scaled by 1 - HEADROOM w
MARK = "# design:"


@dataclass(frozen=True)
class Change:
    """One value the design changes: key path, new and old value, and why."""

    path: tuple
    value: Any
    old: Any
    why: str


@dataclass(frozen=True)
class Design:
    """The designed plan (text and parsed), what changed and the notes on the whole design."""

    plan: Plan
    changes: tuple[Change, ...]
    notes: tuple[str, ...]


def choose_seeds(*, register_length: int, n_axes: int, flown: set[tuple[int, int]]
                 ) -> tuple[list[int], int]:
    """Seeds for ``n_axes`` PRBS of one register, N // n_axes chips apart, placed where the
    nearest start of a flown PRBS of that register (``(register_length, seed)`` pairs) is
    farthest; no seed equals a flown one. Returns the seeds and that distance in chips (-1 when
    no PRBS of this register was flown)."""
    n, big = register_length, (1 << register_length) - 1
    step = max(1, big // n_axes)
    starts = np.array([prbs_shift(register_length=n, seed_a=1, seed_b=s)
                       for r, s in sorted(flown) if r == n], dtype=np.int64)
    cands = np.arange(big, dtype=np.int64)[:: max(1, big // 65536)]
    score = np.full(cands.size, big, dtype=np.int64)
    for i in range(n_axes):
        for p in starts:
            d = (cands + i * step - p) % big
            score = np.minimum(score, np.minimum(d, big - d))
    taken = {s for _, s in flown}
    if starts.size == 0:
        score[:] = -1  # nothing flown on this register: any start, the first that is new
    for k in np.lexsort((cands, -score)):
        seeds = [advanced_seed(register_length=n, seed=1, chips=int(cands[k]) + i * step)
                 for i in range(n_axes)]
        if not taken & set(seeds):
            return seeds, int(score[k])
    raise PlanError(f"no {n}-bit PRBS seeds left that differ from the flown ones; "
                    "design a longer register")


def _factor(x: float) -> str:
    """A scale factor with the digits that tell it from 1 (``0.998``, not ``1.00``): a note
    ``x1.00`` beside a value that changed reads as a contradiction."""
    for digits in range(2, 7):
        text = f"{x:.{digits}f}"
        if x == 1 or float(text) != 1:
            return text
    return f"{x:.12g}"


def _fmt(value: Any) -> str:
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, float):
        return f"{value:.1f}" if value == round(value, 1) else f"{value:.4g}"
    return str(value)


def _strip_comment(line: str) -> str:
    """The line without its trailing comment (a ``#`` outside strings)."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            quote = None if c == quote else quote
        elif c in "\"'":
            quote = c
        elif c == "#":
            return line[:i].rstrip()
    return line.rstrip()


def design_notes(text: str) -> tuple[list[str], list[tuple[str, str]]]:
    """The ``# design:`` notes of a plan text: the header lines, and ``(key, why)`` for every
    key line that carries one (what ``plan show`` prints)."""
    header: list[str] = []
    by_line: dict[int, tuple] = {}
    for path, row in key_lines(text).items():
        if len(path) > len(by_line.get(row, ())):
            by_line[row] = path
    keys = []
    for row, line in enumerate(text.splitlines(), start=1):
        at = line.find(MARK)
        if at < 0:
            continue
        note = line[at + len(MARK):].strip()
        if not line[:at].strip():
            header.append(note)
        elif row in by_line and _strip_comment(line) == line[:at].rstrip():
            keys.append((dotted(by_line[row]), note))
    return header, keys


def design_plan(plan: Plan, facts: ModelFacts, *, name: str, flown: set[tuple[int, int]],
                saturation: float | None = None, max_saturation: float = MAX_SATURATION,
                aliasing: Mapping[str, float] | None = None,
                firmware: Mapping[str, float] | None = None, source: str = "") -> Design:
    """The next flight: ``plan``'s PRBS re-timed, re-scaled and re-seeded from ``facts`` (module
    docstring); ``flown`` holds ``(register_length, seed)`` of every PRBS already flown (the
    ``plan``'s own are added),
    ``saturation`` the share of the flown excitation's samples with an input at its limit (None:
    not measured); above ``max_saturation`` no amplitude is raised. ``aliasing``: the top-band
    share of each axis' motor combination in the flown sessions
    (:func:`groundstation.plan.aliasing.axis_shares`), ``firmware`` the flown firmware's
    parameters (``group.name``: value). ``source`` names the new plan in errors (its file)."""
    rate = plan.setpoint_rate_hz
    flown = set(flown) | {(e.register_length, e.seed) for p in plan.phases
                          for e in p.excitation if e.signal == "prbs"}  # never fly them again
    w_sv, sv_note = sv_weakness(facts)
    clipped = saturation is not None and saturation > max_saturation
    sat_note = ("inputs at their limits: not measured (no flown session)" if saturation is None
                else f"inputs at their limits in {100 * saturation:.1f} % of the flown "
                f"excitation (amplitudes raised only below {100 * max_saturation:g} %)")
    changes: list[Change] = []
    if name != plan.name:
        changes.append(Change(("name",), name, plan.name, "the output file's name"))
    prbs_phases = [(i, p) for i, p in enumerate(plan.phases)
                   if any(e.signal == "prbs" for e in p.excitation)]
    if not prbs_phases:
        raise PlanError(f"{plan.source}: plan '{plan.name}' has no PRBS excitation to design; "
                        "start from one that has (e.g. --from prbs-3axis)")
    fits_used: dict[str, str] = {}
    chip_notes: list[str] = []
    for i, phase in prbs_phases:
        chains = [e for e in phase.excitation if e.signal == "prbs"]
        axes = {e.axis: axis_fit(facts, e.axis) for e in chains if e.axis in _LIMIT}
        weak = {a: weakness(fit=fit, sv_weakness=w_sv) for a, (_, fit) in axes.items()}
        doubt, flown_clock = chip_doubt(axes, sv_weak=w_sv), min(e.clock_period for e in chains)
        rule = {"poles": facts.poles, "dt": facts.dt, "rate_hz": rate, "n_ticks": phase.n_ticks,
                "horizon_ticks": facts.horizon_samples * facts.dt * rate}
        flown_period = min(phase.n_ticks, max(((1 << e.register_length) - 1) * e.clock_period
                                              for e in chains))  # ticks, as much as flew
        timing = prbs_timing(**rule, max_clock=flown_clock if doubt else None,
                             min_period_ticks=flown_period if doubt else 0, untrusted=doubt)
        if timing and timing.capped:
            chip_notes.append(f"phase[{i}] PRBS {timing.why_clock}")
        worst = max(weak, key=weak.__getitem__) if weak else None
        for e in chains:
            if e.axis not in _LIMIT:
                continue
            out, fit = axes[e.axis]
            limit = getattr(plan.vehicle, _LIMIT[e.axis])
            w = weak[e.axis]
            fits_used[out] = "?" if fit is None else f"{fit:.1f}"
            fit_text = "no fit" if fit is None else f"fit {out} {fit:.1f} %"
            if clipped:  # no raise; room for the worst-explained axis (module docstring)
                gain = 1.0 - HEADROOM * (weak[worst] - w)
                amp = math.floor(e.amplitude * gain * 10 + 1e-9) / 10
                if amp < e.amplitude:
                    changes.append(Change(
                        ("phase", i, e.axis, "amplitude"), amp, e.amplitude,
                        f"{fit_text}, weakness {w:.2f}; inputs at their limits and "
                        f"{axes[worst][0]} explained worst (weakness {weak[worst]:.2f}): "
                        f"x{_factor(gain)}, rounded down to 0.1, to leave it the motors' "
                        "room"))
                continue
            amp = math.floor(min(e.amplitude * (1 + w), LIMIT_SHARE * limit) * 10 + 1e-9) / 10
            if amp > e.amplitude:
                changes.append(Change(
                    ("phase", i, e.axis, "amplitude"), amp, e.amplitude,
                    f"{fit_text}, weakness {w:.2f}: x{_factor(1 + w)}, at most "
                    f"{LIMIT_SHARE:g} x vehicle.{_LIMIT[e.axis]} = {LIMIT_SHARE * limit:g}"))
        if timing:
            clock, n, why_clock, why_reg = (timing.clock, timing.register_length,
                                            timing.why_clock, timing.why_register)
        else:
            clock, n = chains[0].clock_period, chains[0].register_length
            why_clock = why_reg = ("no mode below the setpoint Nyquist settles within the "
                                   "phase: as before")
        seeds, apart = choose_seeds(register_length=n, n_axes=len(chains), flown=flown)
        flown |= {(n, s) for s in seeds}
        for e, seed in zip(chains, seeds, strict=True):
            base = ("phase", i, e.axis)
            if clock != e.clock_period:
                changes.append(Change((*base, "clock_period"), clock, e.clock_period, why_clock))
            if n != e.register_length:
                uses_period = "period" in _raw_table(plan, base)
                changes.append(Change((*base, "period" if uses_period else "register_length"),
                                      (1 << n) - 1 if uses_period else n,
                                      e.register_length, why_reg))
            far = (f">= {apart} chips from every flown start" if apart >= 0 else
                   f"no {n}-bit PRBS flown yet, and unlike every flown seed")
            spacing = (f"{max(1, ((1 << n) - 1) // len(chains))} chips from the other axes"
                       if len(chains) > 1 else "the phase's only PRBS axis")
            changes.append(Change((*base, "seed"), seed, e.seed, f"{spacing}; {far}"))
    changes += [Change(*c) for c in d_term_changes(plan, aliasing=aliasing or {},
                                                   firmware=firmware or {})]
    changes = [replace(c, why=f"{c.why}; was {_fmt(c.old)}") for c in changes]
    fits_text = ", ".join(f"{k} {v}" for k, v in fits_used.items())
    notes = (f"designed from {facts.source} by `groundstation plan design` (from {plan.name})",
             f"model: {len(facts.poles)} states at {facts.dt:g} s; fits: {fits_text} % "
             f"({facts.fit_source})",
             sv_note, sat_note
             + ("; no amplitude raised (more would be clipped), the better-explained axes "
                "lowered to leave the worst the motors' room" if clipped else ""),
             "motor logs: " + (", ".join(f"{a} {100 * v:.1f} %" for a, v in aliasing.items())
                               + " of each axis' power in the top third of the band"
                               if aliasing else "not measured (no flown session, or the "
                               "model's inputs are not motor.m1..m4)"),
             *chip_notes,
             "rules and equations: docs/flightplans.md, 'Designing the next flight'")
    header = "".join(f"{MARK} {comment_text(n)}\n" for n in notes)  # names from files
    earlier = f"{MARK} (earlier design)"
    kept = "".join(ln.replace(MARK, earlier) if MARK in ln and earlier not in ln else ln
                   for ln in plan.text.splitlines(keepends=True)
                   if not ln.lstrip().startswith(MARK))  # an earlier design's notes
    for c in changes:
        if c.path[0] == "parameters":
            kept = ensure_tables(kept, path=c.path[:-1])
    text = header + set_keys(kept, edits=[(c.path, c.value, c.why) for c in changes], mark=MARK)
    new = parse_plan(text=text, source=source or f"{name} (designed)", name=name)
    _verify(new, changes)
    return Design(plan=new, changes=tuple(changes), notes=notes)


def _raw_table(plan: Plan, path: tuple) -> dict:
    data: Any = tomllib.loads(plan.text)
    for key in path:
        data = data[key]
    return data


def _verify(plan: Plan, changes: list[Change]) -> None:
    """Every designed value is in the parsed plan (never fly what was not designed)."""
    params = dict(plan.parameters)
    for ch in changes:
        if ch.path[0] == "parameters":
            got = params.get(".".join(ch.path[1:]))
            if got is None or not math.isclose(got, ch.value):
                raise PlanError(f"{plan.source}: could not write {dotted(ch.path)} (got {got}, "
                                f"wanted {ch.value})")
            continue
        if ch.path[0] != "phase":
            continue
        spec = next(e for e in plan.phases[ch.path[1]].excitation if e.axis == ch.path[2])
        key = "register_length" if ch.path[3] == "period" else ch.path[3]
        got = getattr(spec, key)
        want = ch.value if ch.path[3] != "period" else int(ch.value).bit_length()
        if not math.isclose(got, want):
            raise PlanError(f"{plan.source}: could not write {dotted(ch.path)} (got {got}, "
                            f"wanted {want})")
