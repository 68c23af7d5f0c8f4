"""The next flight's excitation, designed from an identified model (``groundstation plan design``).

Numbers in, plan text out: :class:`ModelFacts` holds what the design needs from a model (poles,
``dt``, channel names, singular values, horizons, fits per output), so this module loads no
identification code; the command reads the model file (with ``sysid``'s hardened loader, inside
the function) and hands the numbers over. :func:`design_plan` edits the ``--from`` plan's text
with :func:`~groundstation.plan.toml.set_keys` (tomlkit: its comments and layout kept, every
changed value with a ``# design:`` comment saying why) and parses the result again, so the plan
written is the plan checked. The rules, with their equations, are in ``docs/flightplans.md``
("Designing the next flight"):

* PRBS chip :math:`T_{sw} \\le 2.78\\,\\tau_L / \\alpha_s` and period
  :math:`N T_{sw} \\ge 2\\pi \\beta_s \\tau_H` (Rivera and Jun 2000): :math:`\\tau_L = 1 / |s|`
  of the fastest mode below the setpoints' Nyquist frequency,
  :math:`\\tau_H = 1 / |\\mathrm{Re}\\,s|` of the slowest that settles within
  the phase (:math:`s = \\ln z / dt`), in whole setpoint ticks, the period at most the phase;
  the chip lengthened beyond the flown one only by a model that explains every excited axis
  well (:func:`_doubt`: a model missing the fast modes over-estimates :math:`\\tau_L`);
* amplitude :math:`a = \\min(a_0 (1 + w), 0.9\\,L)` (never below :math:`a_0`, never beyond the
  limit :math:`L`), :math:`w` the axis' weakness from its fit and the singular values; never
  raised when the flown excitation already drove the model's inputs (the motors) to their
  limits in more than 1 % of its samples (:func:`saturated`): more amplitude would be clipped,
  a nonlinearity no linear model explains. The motors' range is then shared out instead: an
  axis explained better than the worst gets :math:`a = a_0 (1 - 0.5 (w_{worst} - w))`, the
  worst keeps :math:`a_0`;
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
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from groundstation.errors import PlanError
from groundstation.plan import Plan, parse_plan
from groundstation.plan.aliasing import d_term_changes
from groundstation.plan.excitation import prbs_shift
from groundstation.plan.timing import prbs_timing
from groundstation.plan.toml import dotted, ensure_tables, key_lines, set_keys
from groundstation.plan.variants import advanced_seed

__all__ = ["AXIS_OUTPUTS", "MAX_SATURATION", "Change", "Design", "ModelFacts", "choose_seeds",
           "design_notes", "design_plan", "prbs_timing", "saturated", "weakness"]

AXIS_OUTPUTS = {"roll": ("gyro.x", "controller.r_roll", "stateEstimate.roll", "stabilizer.roll"),
                "pitch": ("gyro.y", "controller.r_pitch", "stateEstimate.pitch",
                          "stabilizer.pitch"),
                "yaw_rate": ("gyro.z", "controller.r_yaw")}
"""Model outputs that measure each setpoint axis, in order of preference."""
_LIMIT = {"roll": "max_roll_deg", "pitch": "max_pitch_deg", "yaw_rate": "max_yaw_rate_deg_s"}
FIT_GOOD, FIT_POOR = 90.0, 50.0  # % fit: weakness 0 at or above FIT_GOOD, 1 at or below FIT_POOR
SV_GOOD = 10.0  # sigma_n / median(discarded sigmas) at or above this: the order is well supported
LIMIT_SHARE = 0.9  # amplitudes at most 0.9 x the vehicle limit (and at most 2x: weakness <= 1)
MAX_SATURATION = 0.01  # inputs at their limits in more of the flown excitation: no raise
HEADROOM = 0.5  # clipped: an axis w less weak than the weakest is scaled by 1 - HEADROOM w
PLATEAU = 0.01  # an input's extreme value held in more than this share of samples: a limit
MARK = "# design:"


@dataclass(frozen=True)
class ModelFacts:
    """What the design reads from a model file; ``fits`` maps output name to fit %."""

    source: str
    poles: np.ndarray
    dt: float
    output_names: tuple[str, ...]
    singular_values: np.ndarray | None = None
    horizon_samples: int = 0  # past + future of the identification
    fits: dict[str, float] = field(default_factory=dict)
    fit_source: str = "no fits"

    @classmethod
    def from_model(cls, model: Any, *, source: str, fits: dict[str, float] | None = None,
                   fit_source: str = "") -> ModelFacts:
        """The facts of a ``sysid`` model (duck-typed, nothing imported). Without measured
        ``fits``: the provenance's ``fit_percent`` if it has one, else the one-step fit the
        model implies, 100 (1 - sigma_e / sigma_y) from its innovation covariance and the
        identification data's output scale."""
        prov = model.provenance if isinstance(model.provenance, dict) else {}
        names = tuple(model.output_names)
        if fits is None:
            fits, fit_source = _stored_fits(prov, names=names, noise_cov=model.noise_cov)
        sv = prov.get("singular_values")
        sv = np.asarray(sv, dtype=float).ravel() if isinstance(sv, list) and sv else None
        horizons = [prov.get(k) for k in ("past", "future")]
        h = sum(horizons) if all(type(v) is int and v > 0 for v in horizons) else 0
        return cls(source=source, poles=np.linalg.eigvals(model.A), dt=float(model.dt),
                   output_names=names, singular_values=sv, horizon_samples=h,
                   fits=dict(fits), fit_source=fit_source or "no fits")


def _stored_fits(prov: dict, *, names: tuple[str, ...], noise_cov: Any
                 ) -> tuple[dict[str, float], str]:
    raw = prov.get("fit_percent")
    if isinstance(raw, dict):  # {output: %} or, as `sysid identify --json`, {mode: {output: %}}
        raw = next((raw[m] for m in ("simulation", "1-step") if isinstance(raw.get(m), dict)),
                   raw)
        got = {k: float(v) for k, v in raw.items() if k in names
               and isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)}
        if got:
            return got, "fits stored in the model's provenance"
    scaling = prov.get("scaling")
    scale = scaling.get("y_scale") if isinstance(scaling, dict) else None
    if noise_cov is None or not isinstance(scale, list) or len(scale) != len(names):
        return {}, "no fits"
    sd = np.sqrt(np.clip(np.diag(np.asarray(noise_cov, dtype=float)), 0, None))
    fits = {n: float(100 * (1 - e / s)) for n, e, s in zip(names, sd, scale, strict=True)
            if isinstance(s, int | float) and s > 0}
    return fits, "1-step fits the model implies (innovation std / output std)"


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


def saturated(u: np.ndarray) -> np.ndarray:
    """``(N,)`` True where any input of ``u (N, m)`` sits at a limit: its largest or smallest
    value, when that value is held in more than 1 % of the samples (a plateau, as a motor
    command at 65535 PWM; a free signal touches its extremes once)."""
    u = np.asarray(u, dtype=float)
    at = np.zeros(u.shape[0], dtype=bool)
    for col in u.T:
        for ext in (col.max(initial=-np.inf), col.min(initial=np.inf)):
            hit = col == ext
            if hit.mean() > PLATEAU:
                at |= hit
    return at


def weakness(*, fit: float | None, sv_weakness: float) -> float:
    """0 (explained well) to 1 (poorly): from the fit (90 % -> 0, 50 % -> 1) and the singular
    values' weakness, whichever is larger."""
    w = 0.0 if fit is None else (FIT_GOOD - fit) / (FIT_GOOD - FIT_POOR)
    return float(min(1.0, max(0.0, w, sv_weakness)))


def _doubt(axes: dict[str, tuple[str, float | None]], *, sv_weak: float) -> str:
    """Why the model is not trusted to lengthen the PRBS chip ("" when it is). Rivera and
    Jun's rule wants a *low* estimate of the time constants; a model that explains an excited
    axis poorly (fit below ``FIT_GOOD``), whose fits are unknown, or whose order the singular
    values support weakly may miss the fast modes that a short chip excites (a 5-state model
    of a ``sim://`` flight saw nothing faster than 1.7 s and asked for 2.2 s chips at +-25 deg
    of roll). Shortening the chip is always allowed."""
    miss = "it may miss the fast modes a short chip excites"
    unknown = [out for out, fit in axes.values() if fit is None]
    if unknown:
        return f"the model's fit of {', '.join(unknown)} is not known: {miss}"
    poor = [f"{out} at {fit:.1f} %" for out, fit in axes.values()
            if fit is not None and fit < FIT_GOOD]
    if poor:
        return f"the model explains {', '.join(poor)} (below {FIT_GOOD:g} %): {miss}"
    if sv_weak > 0.0:
        return f"the singular values support its order weakly (weakness {sv_weak:.2f}): {miss}"
    return ""


def sv_weakness(facts: ModelFacts) -> tuple[float, str]:
    """How close the smallest kept singular value is to the noise floor (the median of the
    discarded ones): ratio >= 10 -> 0, ratio 1 -> 1, log scale between."""
    sv, n = facts.singular_values, len(facts.poles)
    if sv is None or len(sv) <= n or n == 0 or not np.median(sv[n:]) > 0:
        return 0.0, "singular values: not stored"
    ratio = float(sv[n - 1] / np.median(sv[n:]))
    w = min(1.0, max(0.0, math.log(SV_GOOD / ratio) / math.log(SV_GOOD))) if ratio > 0 else 1.0
    return w, (f"singular values: sigma_{n} / median(discarded) = {ratio:.3g} "
               f"(weakness {w:.2f}; 0 at >= {SV_GOOD:g})")


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


def _axis_fit(facts: ModelFacts, axis: str) -> tuple[str, float | None]:
    name = next((n for n in AXIS_OUTPUTS[axis] if n in facts.output_names), None)
    if name is None:
        raise PlanError(
            f"{facts.source}: the model has no output for the plan's {axis} axis (looked for "
            f"{', '.join(AXIS_OUTPUTS[axis])}; its outputs are {', '.join(facts.output_names)});"
            " identify with the gyro outputs, or design from a plan without that axis")
    return name, facts.fits.get(name)


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
        axes = {e.axis: _axis_fit(facts, e.axis) for e in chains if e.axis in _LIMIT}
        weak = {a: weakness(fit=fit, sv_weakness=w_sv) for a, (_, fit) in axes.items()}
        doubt, flown_clock = _doubt(axes, sv_weak=w_sv), min(e.clock_period for e in chains)
        rule = {"poles": facts.poles, "dt": facts.dt, "rate_hz": rate, "n_ticks": phase.n_ticks,
                "horizon_ticks": facts.horizon_samples * facts.dt * rate}
        timing = prbs_timing(**rule, max_clock=flown_clock if doubt else None,
                             untrusted=doubt)
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
                        f"x{gain:.2f} to leave it the motors' room"))
                continue
            amp = math.floor(min(e.amplitude * (1 + w), LIMIT_SHARE * limit) * 10 + 1e-9) / 10
            if amp > e.amplitude:
                changes.append(Change(
                    ("phase", i, e.axis, "amplitude"), amp, e.amplitude,
                    f"{fit_text}, weakness {w:.2f}: x{1 + w:.2f}, at most "
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
            changes.append(Change((*base, "seed"), seed, e.seed,
                                  f"{max(1, ((1 << n) - 1) // len(chains))} chips from the "
                                  f"other axes; {far}"))
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
    header = "".join(f"{MARK} {n}\n" for n in notes)
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
