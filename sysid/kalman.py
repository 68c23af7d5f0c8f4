"""A stable one-step predictor for an identified innovation model (steady-state Kalman gain).

An innovation model ``x(k+1) = A x(k) + B u(k) + K e(k)``, ``y(k) = C x(k) + D u(k) + e(k)``
identified from data can come with a predictor ``A - K C`` that is unstable; its k-step
predictions (:func:`sysid.validate.predict`) then diverge. :func:`stable_predictor` replaces
K by the steady-state Kalman gain of the model's own noise description, which keeps the output
spectrum and makes ``A - K C`` stable whenever ``(A, C)`` is detectable.

:func:`one_step_errors` runs a model's one-step predictor over flights (with that gain when its
own diverges) and :func:`error_covariance` is the covariance of the errors: what residual
analysis, the information criteria and every identified model's ``noise_cov``
(:mod:`sysid.innovation_cov`) are computed from.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np

from sysid.data import IOData, as_flights
from sysid.errors import DataError, DimensionError
from sysid.model import StateSpaceModel
from sysid.validate import predict

__all__ = ["error_covariance", "one_step_errors", "stable_predictor"]

log = logging.getLogger("sysid.validate")  # reported with the validation it serves


def _kalman_gain(
    *, A: np.ndarray, C: np.ndarray, K: np.ndarray, noise_cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state Kalman gain of the innovation model ``(A, C, K, noise_cov)``.

    The model is a state-space noise description with process noise :math:`w = Ke`,
    measurement noise :math:`v = e`: :math:`Q = K R K^T`, :math:`S = K R`, :math:`R`. The
    stabilising solution :math:`P` of the filter DARE gives
    :math:`K' = (A P C^T + S)(C P C^T + R)^{-1}` and innovation covariance
    :math:`R' = C P C^T + R`. If :math:`A - KC` is already stable, :math:`P = 0` and
    :math:`K' = K`; otherwise the zeros of the noise model outside the unit circle are
    reflected inside (same output spectrum, minimum-phase factor). Returns ``(K', R')``.
    """
    from scipy.linalg import solve_discrete_are

    q, s = K @ noise_cov @ K.T, K @ noise_cov
    try:
        p = solve_discrete_are(A.T, C.T, q, noise_cov, s=s)
    except (np.linalg.LinAlgError, ValueError) as exc:
        raise DataError(
            f"no stabilising Kalman gain: (A, C) is not detectable or A - KC has a pole on the "
            f"unit circle ({exc}); re-identify with another order or horizons"
        ) from exc
    r_new = C @ p @ C.T + noise_cov
    return (A @ p @ C.T + s) @ np.linalg.inv(r_new), r_new


def stable_predictor(
    model: StateSpaceModel,
    *,
    data: IOData | Sequence[IOData] | None = None,
    noise_cov: np.ndarray | None = None,
) -> StateSpaceModel:
    """The model with a stable one-step predictor: K replaced by the steady-state Kalman gain.

    The gain comes from the DARE of the model's own noise description (see
    :func:`_kalman_gain`) with innovation covariance ``noise_cov`` (l, l), else
    ``model.noise_cov``, else the identity (for a single output the gain does not depend on it).
    A, B, C, D are unchanged, so simulation is unchanged; ``A - K C`` becomes stable whenever
    ``(A, C)`` is detectable. The returned ``noise_cov`` is the new innovation covariance, or,
    if ``data`` is given, the covariance of the new predictor's one-step errors on it
    (:func:`error_covariance`, the convention of identified models).
    A model whose predictor is already stable is returned as it is.
    """
    if model.predictor_is_stable:
        return model
    ell = model.n_outputs
    r = noise_cov if noise_cov is not None else model.noise_cov
    r = np.eye(ell) if r is None else np.asarray(r, dtype=float)
    if r.shape != (ell, ell):
        raise DimensionError(f"noise_cov has shape {r.shape}; pass ({ell}, {ell})")
    k_new, r_new = _kalman_gain(A=model.A, C=model.C, K=model.K, noise_cov=r)
    before = float(np.max(np.abs(model.predictor_poles())))
    out = model.replace(K=k_new, noise_cov=r_new, provenance={
        **model.provenance, "predictor": "steady-state Kalman gain (sysid.stable_predictor)",
        "predictor_radius_before": before,
    })
    if data is not None:
        errs, _ = one_step_errors(out, flights=as_flights(data))
        out = out.replace(noise_cov=error_covariance(errs))
    log.info("predictor stabilised: max |eig(A - KC)| %.4f -> %.4f", before,
             float(np.max(np.abs(out.predictor_poles()))))
    return out


def one_step_errors(model: StateSpaceModel, *, flights: Sequence[IOData]
                    ) -> tuple[list[np.ndarray], bool]:
    """The one-step prediction errors :math:`y(t) - \\hat y(t|t-1)` of ``model``, ``(N_i, l)``
    per flight, each flight from its own least-squares initial state
    (:func:`sysid.validate.predict`), and whether the predictor was stabilised: a model whose
    ``A - K C`` is unstable is run with its steady-state Kalman gain
    (:func:`sysid.stable_predictor`), as its own predictor diverges. Errors that overflow are
    returned as they are (inf, NaN) for the caller to judge."""
    stabilised = not model.predictor_is_stable
    if stabilised:
        model = stable_predictor(model)
    errs = []
    for d in flights:
        with np.errstate(over="ignore", invalid="ignore"):
            errs.append(d.y - predict(model, u=d.u, y=d.y, horizon=1)[0])
    return errs, stabilised


def error_covariance(errors: Sequence[np.ndarray]) -> np.ndarray:
    """``(l, l)`` :math:`\\frac1N \\sum_t e(t) e(t)^T` over the errors ``(N_i, l)`` of all flights,
    ``N`` their total count (no mean removed: the model's innovations have mean zero)."""
    e = np.vstack(errors)
    return e.T @ e / e.shape[0]
