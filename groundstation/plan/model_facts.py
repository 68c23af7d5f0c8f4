"""What the design of the next flight knows of a model, and how well the model explains each
axis (``groundstation plan design``; the rules in ``docs/flightplans.md``, "Designing the next
flight").

:class:`ModelFacts` holds numbers only (poles, ``dt``, output names, singular values, horizons,
fits per output), read from a ``sysid`` model by duck typing, so nothing here imports
identification code. An axis is *weak* (:func:`weakness`, 0 to 1) when its output's fit is below
:data:`FIT_GOOD` or the singular values support the model's order poorly (:func:`sv_weakness`);
:func:`chip_doubt` says why the model is not trusted to lengthen the PRBS chip, :func:`saturated`
where flown inputs sat at a limit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from groundstation.errors import PlanError

__all__ = ["AXIS_OUTPUTS", "FIT_GOOD", "ModelFacts", "axis_fit", "chip_doubt", "saturated",
           "stored_fits", "sv_weakness", "weakness"]

AXIS_OUTPUTS = {"roll": ("gyro.x", "controller.r_roll", "stateEstimate.roll", "stabilizer.roll"),
                "pitch": ("gyro.y", "controller.r_pitch", "stateEstimate.pitch",
                          "stabilizer.pitch"),
                "yaw_rate": ("gyro.z", "controller.r_yaw")}
"""Model outputs that measure each setpoint axis, in order of preference."""
FIT_GOOD, FIT_POOR = 90.0, 50.0  # % fit: weakness 0 at or above FIT_GOOD, 1 at or below FIT_POOR
SV_GOOD = 10.0  # sigma_n / median(discarded sigmas) at or above this: the order is well supported
PLATEAU = 0.01  # an input's extreme value held in more than this share of samples: a limit


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
            fits, fit_source = stored_fits(prov, names=names, noise_cov=model.noise_cov)
        sv = prov.get("singular_values")
        sv = np.asarray(sv, dtype=float).ravel() if isinstance(sv, list) and sv else None
        horizons = [prov.get(k) for k in ("past", "future")]
        h = sum(horizons) if all(type(v) is int and v > 0 for v in horizons) else 0
        return cls(source=source, poles=np.linalg.eigvals(model.A), dt=float(model.dt),
                   output_names=names, singular_values=sv, horizon_samples=h,
                   fits=dict(fits), fit_source=fit_source or "no fits")


def stored_fits(prov: dict, *, names: tuple[str, ...], noise_cov: Any
                ) -> tuple[dict[str, float], str]:
    """Fits per output from a model's provenance: its ``fit_percent``, else the one-step fit
    its innovation covariance implies; and where they came from."""
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


def chip_doubt(axes: dict[str, tuple[str, float | None]], *, sv_weak: float) -> str:
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
    discarded ones up to the data's numerical rank: short horizons leave exact zeros beyond
    it, which made any order look supported): ratio >= 10 -> 0, ratio 1 -> 1, log scale
    between; 1 when the order is the rank itself (no floor to compare with)."""
    sv, n = facts.singular_values, len(facts.poles)
    if sv is None or len(sv) <= n or n == 0 or not np.all(np.isfinite(sv)) or not sv[0] > 0:
        return 0.0, "singular values: not stored"
    sv = np.asarray(sv, dtype=float)
    rank = int(np.sum(sv > sv[0] * len(sv) * np.finfo(float).eps))
    if rank <= n:
        return 1.0, (f"singular values: the order {n} is the rank of the data ({rank} non-zero "
                     "values), no noise floor beyond it (weakness 1.00); longer horizons show one")
    ratio = float(sv[n - 1] / np.median(sv[n:rank]))
    w = min(1.0, max(0.0, math.log(SV_GOOD / ratio) / math.log(SV_GOOD))) if ratio > 0 else 1.0
    return w, (f"singular values: sigma_{n} / median(discarded) = {ratio:.3g} "
               f"(weakness {w:.2f}; 0 at >= {SV_GOOD:g})")


def axis_fit(facts: ModelFacts, axis: str) -> tuple[str, float | None]:
    """The model output that measures setpoint ``axis`` (:data:`AXIS_OUTPUTS`) and its fit, %
    (None if not known); one-line :class:`PlanError` when the model has none."""
    name = next((n for n in AXIS_OUTPUTS[axis] if n in facts.output_names), None)
    if name is None:
        raise PlanError(
            f"{facts.source}: the model has no output for the plan's {axis} axis (looked for "
            f"{', '.join(AXIS_OUTPUTS[axis])}; its outputs are {', '.join(facts.output_names)});"
            " identify with the gyro outputs, or design from a plan without that axis")
    return name, facts.fits.get(name)
