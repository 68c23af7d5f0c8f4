"""The step every subspace method shares after its SVD: from Γ_f to ``(A, B, C, D, K)``.

Both IEM and PO-MOESP end with an estimate :math:`\\hat\\Gamma_f` ``(f l, n)`` and a map
:math:`\\widehat{\\Gamma_f L_p}` ``(f l, p c)`` from the past window to the predicted future
(IEM: the row regressions; PO-MOESP: the oblique projection
:math:`L_{Y_f Z_p} L_{Z_p Z_p}^{-1}`). From them:

1. A, C by shift invariance (:func:`sysid.realize.ac_from_gamma`); A treated for stability
   (:mod:`sysid.stability`).
2. States :math:`\\hat x(k) = \\hat L_p Z_p`, :math:`\\hat x(k+1) = \\hat L_p Z_p^+` with
   :math:`\\hat L_p = \\hat\\Gamma_f^\\dagger \\widehat{\\Gamma_f L_p}`; B, D, K by regression on
   them (:func:`sysid.realize.bdk_from_states`), given the final A. If ``A - K C`` is unstable,
   K is the Kalman gain of the state residuals.
3. B, D and one x0 per flight re-estimated with A, C (and K) held, by least squares on

   * ``focus="prediction"``: the one-step prediction error of the predictor
     ``(A - K C, B - K D, K, C, D)`` (:func:`sysid.realize.predictor_fit` with K held); kept
     from step 2 when ``A - K C`` is unstable or nearly defective (:data:`ONE_STEP_MAX_COND`);
   * ``focus="simulation"``: the output (simulation) error
     (:func:`sysid.output_error.output_error_bd`).

Which focus when (``docs/sysid.md``, "Focus"): *prediction* stays consistent in closed loop
(K from the state regression, whose innovation regressor absorbs the inputs' correlation with
the noise; the one-step fit's regressors are past data); use it for closed-loop flight data and
for k-step prediction. *Simulation* minimises the
simulation error of the deterministic part; it is what open-loop data with colored inputs want
(MATLAB ``n4sid`` ``Focus="simulation"``), and is biased by feedback.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from sysid.errors import ParameterError
from sysid.factor import DataProducts
from sysid.model import StateSpaceModel
from sysid.output_error import output_error_bd
from sysid.realize import (
    PredictorFit,
    Signals,
    ac_from_gamma,
    bdk_from_states,
    build_model,
    kalman_gain_from_residuals,
    predictor_fit,
)
from sysid.stability import Stability, check_stability, stabilize

__all__ = ["FOCUS_MODES", "Finished", "Focus", "check_flags", "check_focus", "finish",
           "stability_report"]

log = logging.getLogger(__name__)

Focus = Literal["prediction", "simulation"]
#: Largest condition number of ``A - K C``'s eigenvectors for the prediction focus's one-step
#: B, D fit (above it, nearly repeated poles: the state regression's B, D are kept).
ONE_STEP_MAX_COND = 1e4
FOCUS_MODES: tuple[str, ...] = ("prediction", "simulation")


def check_focus(focus: object) -> None:
    """Raise :class:`ParameterError` unless ``focus`` is one of the modes."""
    if focus not in FOCUS_MODES:
        raise ParameterError(f"focus={focus!r}; use one of {FOCUS_MODES}")


def check_flags(**flags: object) -> None:
    """Raise :class:`ParameterError` for an on/off option that is not a bool: ``"no"`` and
    ``"false"`` are true in Python, so they would switch the option on."""
    for name, value in flags.items():
        if not isinstance(value, bool | np.bool_):
            raise ParameterError(f"{name}={value!r}; pass True or False")


@dataclass(frozen=True, eq=False)
class Finished:
    """Matrices in scaled units and what was done: ``x0`` one ``(n,)`` per flight (fitted with
    B, D by either focus; zeros where the state regression's B, D are kept), ``moved`` the
    poles the stability mode changed, ``notes`` text."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    k: np.ndarray
    noise_cov: np.ndarray
    x0: list[np.ndarray]
    moved: list[tuple[complex, complex]]
    notes: dict[str, str] = field(default_factory=dict)


def finish(*, gamma: np.ndarray, gamma_lp: np.ndarray, sig: Signals, feedthrough: bool,
           focus: Focus, stability: Stability,
           flights: Sequence[tuple[np.ndarray, np.ndarray]],
           bd: tuple[np.ndarray, np.ndarray] | None = None) -> Finished:
    """Steps 1-3 of the module docstring.

    ``gamma`` ``(f l, n)``, ``gamma_lp`` ``(f l, p c)``, ``sig`` the row signals in one column
    basis, ``flights`` the scaled ``(u (N, m), y (N, l))`` of each flight (for output error).
    ``bd``: B, D fixed by the caller (the thesis' eq. 3.15); then only K is regressed and
    ``focus`` must be "prediction".
    """
    check_focus(focus)
    check_stability(stability)
    ell = sig.y0.shape[0]
    a, c = ac_from_gamma(gamma, n_outputs=ell)
    a, moved = stabilize(a, mode=stability)
    lp = np.linalg.pinv(gamma) @ gamma_lp
    x, x_next = lp @ sig.zp, lp @ sig.zp_next
    notes: dict[str, str] = {}
    if bd is None:
        b, d, k = bdk_from_states(a=a, c=c, x=x, x_next=x_next, sig=sig,
                                  feedthrough=feedthrough)
        notes["bd"] = "state regression"
    else:
        b, d, k = bdk_from_states(a=a, c=c, x=x, x_next=x_next, sig=sig,
                                  feedthrough=feedthrough, b=bd[0], d=bd[1])
        notes["bd"] = "thesis eq. 3.15"
    noise_cov = sig.e0 @ sig.e0.T / sig.n_columns
    notes["K"] = "state regression"
    if np.max(np.abs(np.linalg.eigvals(a - k @ c)), initial=0.0) >= 1.0:
        kalman = kalman_gain_from_residuals(a=a, b=b, c=c, d=d, x=x, x_next=x_next, sig=sig)
        if kalman is not None:
            k, noise_cov = kalman
            notes["K"] = "Kalman gain (DARE) of the state residuals"
    n = a.shape[0]
    x0 = [np.zeros(n) for _ in flights]
    if focus == "prediction" and bd is None:
        fit = _one_step_bd(a=a, c=c, k=k, flights=flights, feedthrough=feedthrough)
        if fit is None:
            log.info("prediction focus: A - K C is unstable or nearly defective; B, D from the "
                     "state regression")
        else:
            b, d, x0 = fit.b_k + k @ fit.d, fit.d, fit.x0
            notes["bd"] = "one-step prediction error (prediction focus), x0 per flight"
    if focus == "simulation":
        if bd is not None:
            raise ParameterError("B, D fixed by the thesis variant cannot be re-estimated: "
                                 "use focus='prediction' with variant='thesis'")
        b, d, x0 = output_error_bd(a=a, c=c, flights=flights, feedthrough=feedthrough)
        notes["bd"] = "output error (simulation focus), x0 per flight"
    return Finished(a=a, b=b, c=c, d=d, k=k, noise_cov=noise_cov, x0=x0, moved=moved,
                    notes=notes)


def _one_step_bd(*, a: np.ndarray, c: np.ndarray, k: np.ndarray,
                 flights: Sequence[tuple[np.ndarray, np.ndarray]], feedthrough: bool
                 ) -> PredictorFit | None:
    """Step 3 for the prediction focus: ``B_K = B - K D``, D and x0 by least squares on the
    one-step prediction error of the predictor ``(A - K C, B_K, K, C, D)`` with A, C, K held
    (:func:`sysid.realize.predictor_fit`); None (the state regression's B, D kept) when
    ``A - K C`` is not stable, or close to defective (its eigenvectors' condition number above
    :data:`ONE_STEP_MAX_COND`: the modal regressors' normal equations square it)."""
    a_k = a - k @ c
    lam, vec = np.linalg.eig(a_k)
    if not np.max(np.abs(lam), initial=0.0) < 1.0 or np.linalg.cond(vec) > ONE_STEP_MAX_COND:
        return None
    try:
        return predictor_fit(a_k=a_k, c=c, flights=list(flights), feedthrough=feedthrough,
                             k=k)
    except np.linalg.LinAlgError:
        return None


def stability_report(*, model: StateSpaceModel, fin: Finished, free: Finished,
                     products: DataProducts) -> StateSpaceModel:
    """``model`` with ``provenance["stability"]``: the poles moved and the fit it cost.

    The cost is measured on the identification data with the measure the focus optimises
    (one-step prediction, or simulation as ``sysid compare`` and ``identify`` report it by
    default, :func:`~sysid.validate.default_window`: windows for a model with a pole near the
    unit circle, each from a least-squares x0, else each record whole), against the same
    model with ``stability="free"`` (``free``, scaled units). ``cost_points`` is None when the
    free model's fit is not finite or below -100 % on every channel (it diverges: the move
    costs nothing measurable).
    """
    # validate imports nothing of the methods
    from sysid.validate import compare, default_window

    free_model = build_model(a=free.a, b=free.b, c=free.c, d=free.d, k=free.k,
                             noise_cov=free.noise_cov, u_scale=products.u_scale,
                             y_scale=products.y_scale, template=products.flights[0],
                             provenance={})
    horizon = 1 if model.provenance.get("focus", "prediction") == "prediction" else None
    flights = list(products.flights)
    window = None
    if horizon is None:
        window = default_window(model, n_samples=min(fl.n_samples for fl in flights))
    with np.errstate(all="ignore"):
        fit = np.asarray(compare(model, flights, horizon=horizon, window=window, warn=False))
        fit_free = np.asarray(compare(free_model, flights, horizon=horizon, window=window,
                                      warn=False))
    fit_free = np.where(np.isfinite(fit_free), fit_free, np.nan)
    measurable = np.isfinite(fit_free).any() and np.nanmax(fit_free) > -100.0
    cost = float(np.nanmean(fit_free - fit)) if measurable else None
    report = {
        "mode": model.provenance.get("stability"),
        "moved": [{"from": [p.real, p.imag], "to": [q.real, q.imag], "radius_from": abs(p),
                   "radius_to": abs(q)} for p, q in fin.moved],
        "measure": ("1-step prediction" if horizon == 1
                    else "simulation (each record whole)" if window is None
                    else f"simulation ({window:.3g} s windows)"),
        "fit_percent": fit.tolist(), "fit_percent_free": fit_free.tolist(),
        "cost_points": cost,
    }
    log.info("stability: %d pole(s) moved inside; identification fit cost %s points",
             len(fin.moved), "n/a" if cost is None else f"{cost:.2f}")
    return model.replace(provenance={**model.provenance, "stability": report})
