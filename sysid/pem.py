"""Prediction-error refinement of an innovation model (variable projection over A_K and C).

The one-step predictor of the innovation form (thesis eq. 3.23)

.. math::

    x(k+1) = A_K x(k) + B_K u(k) + K y(k), \\qquad \\hat y(k) = C x(k) + D u(k),
    \\qquad A_K = A - K C

is linear in ``(B_K, K, D, x_0)`` once ``(A_K, C)`` are fixed: those are solved by least squares
inside (:func:`sysid.realize.predictor_fit`), and ``scipy.optimize.least_squares`` moves the
nonlinear parameters ``theta`` to minimise
:math:`V(\\theta) = \\sum_k \\lVert y(k) - \\hat y(k \\mid \\theta, \\hat\\beta(\\theta))\\rVert^2`
(variable projection, Golub & Pereyra).

``theta`` is ``A_K`` in real modal (block-diagonal) form plus the free entries of C:

* a real eigenvalue :math:`\\lambda = \\tanh s` (block ``[lambda]``);
* a complex pair :math:`\\rho e^{\\pm i\\varphi}`, :math:`\\rho = 1/(1+e^{-s})`, block
  ``[[rho cos phi, rho sin phi], [-rho sin phi, rho cos phi]]``;

so the predictor stays stable at every iterate. A state transformation that commutes with
the block (a scalar for a real mode, ``a I + b J`` for a pair) leaves the predictor unchanged;
it is removed by normalising C: in each block the output row with the largest gain is fixed to
``1`` (real mode) or ``(1, 0)`` (pair). That leaves ``n + (l - 1) n`` free parameters.

The result replaces the model only if the cost decreased; otherwise the caller's model is
returned with the reason. Cost per evaluation is one :func:`~sysid.realize.predictor_fit`
(``O(N ((m+l) n)^2)``); the Jacobian is by forward differences, so one iteration costs
``n l + 1`` evaluations.
"""

from __future__ import annotations

import logging
from typing import Literal

import numpy as np
import scipy.optimize

from sysid.output_error import output_error_bd
from sysid.realize import predictor_fit

__all__ = ["modal_form", "pem_refine"]

log = logging.getLogger(__name__)

Matrices = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def modal_form(*, a_k: np.ndarray, c: np.ndarray
               ) -> tuple[np.ndarray, list[int], np.ndarray, np.ndarray] | None:
    """``(eig_params, block_sizes, C_modal (l, n), fixed (l, n) bool)`` of a stable ``A_K``.

    ``C_modal = C T`` with ``T^{-1} A_K T`` block diagonal and the C normalisation of the
    module docstring. None if ``A_K`` is not safely diagonalisable or not stable.
    """
    lam, vec = np.linalg.eig(a_k)
    if np.max(np.abs(lam)) >= 1.0 or np.linalg.cond(vec) > 1e8:
        return None
    cols, sizes, par = [], [], []
    fixed = np.zeros((c.shape[0], a_k.shape[0]), dtype=bool)
    j = 0
    for i, li in enumerate(lam):
        if abs(li.imag) <= 1e-12 * max(1.0, abs(li)):
            v = vec[:, i].real
            cv = c @ v
            r = int(np.argmax(np.abs(cv)))
            cols.append((v / cv[r])[:, None])
            par.append(np.arctanh(li.real))
            sizes.append(1)
            fixed[r, j] = True
            j += 1
        elif li.imag > 0:
            tb = np.stack([vec[:, i].real, vec[:, i].imag], axis=1)
            cb = c @ tb
            r = int(np.argmax(np.linalg.norm(cb, axis=1)))
            c1, c2 = cb[r]
            ab = np.linalg.solve(np.array([[c1, -c2], [c2, c1]]), np.array([1.0, 0.0]))
            cols.append(tb @ np.array([[ab[0], ab[1]], [-ab[1], ab[0]]]))
            rho = abs(li)
            par += [np.log(rho / (1.0 - rho)), float(np.angle(li))]
            sizes.append(2)
            fixed[r, j:j + 2] = True
            j += 2
    c_mod = c @ np.hstack(cols)
    starts = np.cumsum([0, *sizes[:-1]])
    for jj, r in zip(*np.nonzero(fixed.T), strict=True):  # exactly 1 (first column) or 0
        c_mod[r, jj] = 1.0 if jj in starts else 0.0
    return np.array(par), sizes, c_mod, fixed


def _a_k(par: np.ndarray, sizes: list[int]) -> np.ndarray:
    """Block-diagonal ``A_K (n, n)`` from the eigenvalue parameters (module docstring)."""
    n = sum(sizes)
    a = np.zeros((n, n))
    i = j = 0
    for s in sizes:
        if s == 1:
            a[j, j] = np.tanh(par[i])
        else:
            rho = 1.0 / (1.0 + np.exp(-par[i]))
            re, im = rho * np.cos(par[i + 1]), rho * np.sin(par[i + 1])
            a[j:j + 2, j:j + 2] = [[re, im], [-im, re]]
        i += s
        j += s
    return a


def pem_refine(*, matrices: Matrices, flights: list[tuple[np.ndarray, np.ndarray]],
               feedthrough: bool, max_iterations: int = 5,
               criterion: Literal["prediction", "simulation"] = "prediction"
               ) -> tuple[Matrices, str]:
    """Refine ``(A, B, C, D, K, noise_cov)`` by prediction error; returns them and a status.

    ``flights``: ``(u (N, m), y (N, l))`` per flight, in the units of the matrices.
    ``criterion="prediction"`` minimises the one-step prediction errors over ``(A_K, C)`` with
    ``(B_K, K, D, x_0)`` solved inside; on success the model is in the modal basis with
    ``A = A_K + K C``, ``B = B_K + K D`` and ``noise_cov`` the covariance of the prediction
    errors. ``criterion="simulation"`` minimises the simulation (output) errors over
    ``(A, C)`` with ``(B, D, x_0)`` solved inside (:func:`sysid.output_error.output_error_bd`;
    MATLAB ``ssest`` with ``Focus="simulation"``); K is then re-fitted as the Kalman gain of
    the model's noise description when the predictor ``A - K C`` would be unstable. A stays
    stable at every iterate in both. Otherwise the input is returned unchanged and the
    status says why ("kept input model: ...").
    """
    a, _, c, _, k, _ = matrices
    sim = criterion == "simulation"
    modal = modal_form(a_k=a if sim else a - k @ c, c=c)
    if modal is None:
        what = "A" if sim else "A - K C"
        log.warning("PEM refinement skipped: %s unstable or not diagonalisable", what)
        return matrices, f"kept input model: {what} unstable or not diagonalisable"
    par0, sizes, c0, fixed = modal
    free = ~fixed
    n_eig = par0.size
    n_res = sum(y.size for _, y in flights)

    def unpack(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        cm = c0.copy()
        cm[free] = theta[n_eig:]
        return _a_k(theta[:n_eig], sizes), cm

    def inner(theta: np.ndarray) -> tuple | None:
        a_m, cm = unpack(theta)
        if sim:
            return output_error_bd(a=a_m, c=cm, flights=flights, feedthrough=feedthrough,
                                   residuals=True)
        return predictor_fit(a_k=a_m, c=cm, flights=flights, feedthrough=feedthrough,
                             residuals=True)

    def residual(theta: np.ndarray) -> np.ndarray:
        fit = inner(theta)
        if fit is None:  # a pair collapsed onto a defective real pole: make it unattractive
            return np.full(n_res, 1e3)
        errs = np.concatenate([e.ravel() for e in fit[-1]])
        return errs if errs.size == n_res else np.full(n_res, 1e3)

    theta0 = np.concatenate([par0, c0[free]])
    cost0 = 0.5 * float(np.sum(residual(theta0) ** 2))
    sol = scipy.optimize.least_squares(residual, theta0, method="trf",
                                       max_nfev=max_iterations)
    if not sol.cost < cost0:
        log.info("PEM refinement kept the input model: the cost did not decrease")
        return matrices, "kept input model: the prediction-error cost did not decrease"
    a_m, cm = unpack(sol.x)
    fit = inner(sol.x)
    if fit is None or np.max(np.abs(np.linalg.eigvals(a_m))) >= 1.0:
        return matrices, "kept input model: the refined predictor is unusable"
    drop = 100.0 * (1.0 - sol.cost / cost0)
    status = f"done: cost -{drop:.2f} % in {sol.nfev} evaluations ({sol.njev} Jacobians)"
    e = np.vstack(fit[-1])
    cov = e.T @ e / e.shape[0]
    if sim:
        # an output-error model (MATLAB ssest, DisturbanceModel="none"): K = 0 and the
        # covariance of the simulation errors
        return (a_m, fit[0], cm, fit[1], np.zeros_like(k), cov), status + "; output error, K = 0"
    b_k, d, k_new = fit[:3]
    return (a_m + k_new @ cm, b_k + k_new @ d, cm, d, k_new, cov), status
