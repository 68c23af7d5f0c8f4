"""From an estimate of the extended observability matrix to ``(A, B, C, D, K)``.

Signals (rows of the Hankel matrix, residuals, state estimates) are passed as *coordinate*
matrices ``S (rows, K)``: either the raw samples (``K = M`` columns) or their coordinates in the
orthonormal basis ``Q`` of an LQ factorization (``K = r``). Least squares only needs inner
products ``S_1 S_2^T``, which are the same in both, so one implementation serves the fast and
the direct paths.

* Order reduction, thesis eqs. 3.9/3.10/3.32: ``O = U S V^T``,
  :math:`\\hat\\Gamma_f = U_1 S_1^{1/2}`.
* A and C by shift invariance, eqs. 3.11-3.12: ``C`` is the first block row of
  :math:`\\hat\\Gamma_f`, :math:`\\overline{\\Gamma}_f A = \\underline{\\Gamma}_f` by least squares.
* B and D, thesis step 5 (eqs. 3.13-3.15, :func:`bd_thesis`):
  :math:`\\Gamma_f^\\perp Y_f U_f^\\dagger = \\Gamma_f^\\perp H_f`. Consistent in open loop; in
  closed loop :math:`E_f U_f^\\dagger \\ne 0` (the inputs react to the noise) and it is biased.
* B, D and K from the state sequence (default, :func:`bdk_from_states`): with
  :math:`\\hat L_p = \\hat\\Gamma_f^\\dagger \\widehat{\\Gamma_f L_p}` the states are
  :math:`\\hat x(k) = \\hat L_p Z_p` and :math:`\\hat x(k+1) = \\hat L_p Z_p^+` (the past window
  shifted by one sample, eq. 3.23), and with the innovation estimate :math:`\\hat e(k)`

  .. math::

      \\hat x(k+1) - A \\hat x(k) = B u(k) + K \\hat e(k), \\qquad
      y(k) - C \\hat x(k) = D u(k) + \\hat e(k)

  solved by least squares. Both regressors u(k) and ê(k) are included, so the correlation
  between input and noise under feedback causes no bias; the only approximation is
  :math:`A_K^p \\approx 0`, the one IEM already makes.
"""

from __future__ import annotations

import functools
import importlib.metadata
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import scipy.linalg

from sysid.data import IOData
from sysid.errors import OrderError
from sysid.innovation_cov import own_noise_cov
from sysid.model import StateSpaceModel
from sysid.output_error import mode_power

__all__ = [
    "PredictorFit",
    "Signals",
    "ac_from_gamma",
    "bd_thesis",
    "bdk_from_states",
    "build_model",
    "check_order",
    "gamma_from_svd",
    "kalman_gain_from_residuals",
    "lstsq_coords",
    "predictor_fit",
    "refine_predictor",
    "software_versions",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Signals:
    """Row signals in a common column basis (raw samples or LQ coordinates), all ``(rows, K)``.

    ``zp`` past window ``(p c, K)``; ``zp_next`` the past window one sample later; ``u0``, ``y0``
    the first future input/output ``(m, K)``/``(l, K)``; ``e0`` the innovation estimate at that
    time; ``uf``/``yf`` the future blocks ``(f m, K)``/``(f l, K)``; ``n_columns`` Hankel columns M.
    """

    zp: np.ndarray
    zp_next: np.ndarray
    u0: np.ndarray
    y0: np.ndarray
    e0: np.ndarray
    uf: np.ndarray
    yf: np.ndarray
    n_columns: int


def check_order(*, order: int, past: int, future: int, n_inputs: int, n_outputs: int) -> None:
    """Raise :class:`OrderError` unless ``1 <= order <= min((f-1) l, p (m+l))``."""
    by_future = (future - 1) * n_outputs
    by_past = past * (n_inputs + n_outputs)
    limit = min(by_future, by_past)
    if isinstance(order, bool) or not isinstance(order, int | np.integer) or order < 1:
        raise OrderError(f"order={order!r}; pass a positive integer model order")
    if order > limit:
        if by_future <= by_past:
            why = f"(future - 1) x {n_outputs} outputs = {by_future}"
            fix = f"future >= {-(-order // n_outputs) + 1}"
        else:
            why = f"past x {n_inputs + n_outputs} channels = {by_past}"
            fix = f"past >= {-(-order // (n_inputs + n_outputs))}"
        raise OrderError(f"order={order} exceeds the rank available ({why} with past={past}, "
                         f"future={future}); lower the order or use {fix}")


def lstsq_coords(target: np.ndarray, regressors: np.ndarray) -> np.ndarray:
    """``Theta`` minimising ``||target - Theta regressors||_F`` (rows are signals)."""
    return np.linalg.lstsq(regressors.T, target.T, rcond=None)[0].T


def gamma_from_svd(o: np.ndarray | None, *, order: int,
                   cache: dict[Any, Any] | None = None, key: Any = "svd"
                   ) -> tuple[np.ndarray, np.ndarray]:
    """:math:`\\hat\\Gamma_f = U_1 S_1^{1/2}` ``(f l, n)`` and all singular values of ``o``.

    With ``cache`` (e.g. ``DataProducts.cache``) the SVD is taken once under ``key`` and every
    later order reuses it (``o`` may then be None)."""
    if cache is not None and key in cache:
        u, s = cache[key]
    else:
        u, s, _ = np.linalg.svd(o, full_matrices=False)
        if cache is not None:
            cache[key] = (u, s)
    if s[order - 1] <= 1e-12 * s[0]:
        raise OrderError(f"order={order} exceeds the numerical rank of the data "
                         f"({int(np.sum(s > 1e-12 * s[0]))}); lower the order")
    return u[:, :order] * np.sqrt(s[:order]), s


def ac_from_gamma(gamma: np.ndarray, *, n_outputs: int) -> tuple[np.ndarray, np.ndarray]:
    """``A (n, n)``, ``C (l, n)`` from :math:`\\hat\\Gamma_f` (thesis eqs. 3.11-3.12)."""
    c = gamma[:n_outputs]
    a = np.linalg.lstsq(gamma[:-n_outputs], gamma[n_outputs:], rcond=None)[0]
    return a, c


def bd_thesis(*, gamma: np.ndarray, yf_uf_pinv: np.ndarray, n_inputs: int, n_outputs: int,
              feedthrough: bool) -> tuple[np.ndarray, np.ndarray]:
    """B, D from :math:`\\Gamma^\\perp Y_f U_f^\\dagger = \\Gamma^\\perp H_f` (eqs. 3.13-3.15).

    ``yf_uf_pinv`` is :math:`Y_f U_f^\\dagger` ``(f l, f m)``. Column block i of the left side,
    :math:`\\mathcal M_i`, equals :math:`\\mathcal L_i D + \\sum_{j>i} \\mathcal L_j C A^{j-i-1} B`
    with :math:`\\mathcal L_j` the column blocks of :math:`\\Gamma^\\perp` and :math:`CA^k` the
    block rows of :math:`\\hat\\Gamma_f`. With ``feedthrough=False`` D = 0 is imposed.
    """
    m, ell = n_inputs, n_outputs
    f = gamma.shape[0] // ell
    n = gamma.shape[1]
    perp = scipy.linalg.null_space(gamma.T).T  # (f l - n, f l)
    lhs = perp @ yf_uf_pinv
    lj = [perp[:, j * ell:(j + 1) * ell] for j in range(f)]
    gb = [gamma[k * ell:(k + 1) * ell] for k in range(f)]
    rows_d, rows_b, rhs = [], [], []
    for i in range(f):
        acc = np.zeros((perp.shape[0], n))
        for j in range(i + 1, f):
            acc += lj[j] @ gb[j - i - 1]
        rows_d.append(lj[i])
        rows_b.append(acc)
        rhs.append(lhs[:, i * m:(i + 1) * m])
    design = np.hstack([np.vstack(rows_d), np.vstack(rows_b)]) if feedthrough else \
        np.vstack(rows_b)
    sol = np.linalg.lstsq(design, np.vstack(rhs), rcond=None)[0]
    if feedthrough:
        return sol[ell:], sol[:ell]
    return sol, np.zeros((ell, m))


def bdk_from_states(*, a: np.ndarray, c: np.ndarray, x: np.ndarray, x_next: np.ndarray,
                    sig: Signals, feedthrough: bool, b: np.ndarray | None = None,
                    d: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """B, D, K by regression on the estimated states (see module docstring).

    ``x``, ``x_next`` are ``(n, K)`` state coordinates at k and k+1. Given ``b`` (and ``d``)
    only K is estimated (used with the thesis' B, D).
    """
    m, ell = sig.u0.shape[0], sig.y0.shape[0]
    lhs = x_next - a @ x
    if b is None:
        bk = lstsq_coords(lhs, np.vstack([sig.u0, sig.e0]))
        b, k = bk[:, :m], bk[:, m:]
    else:
        k = lstsq_coords(lhs - b @ sig.u0, sig.e0)
    if d is None:
        d = (lstsq_coords(sig.y0 - c @ x, np.vstack([sig.u0, sig.e0]))[:, :m] if feedthrough
             else np.zeros((ell, m)))
    return b, d, k


def kalman_gain_from_residuals(*, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                               x: np.ndarray, x_next: np.ndarray, sig: Signals
                               ) -> tuple[np.ndarray, np.ndarray] | None:
    """Steady-state Kalman gain from the residuals of the state equations (N4SID style).

    ``w = x(k+1) - A x(k) - B u(k)``, ``v = y(k) - C x(k) - D u(k)`` give
    ``[Q S; S^T R] = [w; v][w; v]^T / M``; the stabilising DARE solution P gives
    ``K = (A P C^T + S)(C P C^T + R)^{-1}`` with ``A - K C`` stable whenever (A, C) is
    detectable (Q, R from data are positive semidefinite by construction), and the innovation
    covariance ``C P C^T + R``. Returns None when the DARE has no stabilising solution.
    """
    w = x_next - a @ x - b @ sig.u0
    v = sig.y0 - c @ x - d @ sig.u0
    q, s_, r = (w @ w.T / sig.n_columns, w @ v.T / sig.n_columns, v @ v.T / sig.n_columns)
    try:
        p = scipy.linalg.solve_discrete_are(a.T, c.T, q, r, s=s_)
    except (np.linalg.LinAlgError, ValueError):
        return None
    r_e = c @ p @ c.T + r
    return (a @ p @ c.T + s_) @ np.linalg.inv(r_e), r_e


def _modal_features(lam: np.ndarray, vec: np.ndarray, c: np.ndarray
                    ) -> tuple[list[int], np.ndarray]:
    """Real modal bookkeeping: the eigenvalues kept (real ones, and one of each conjugate
    pair) and ``tau (n, l, n)`` with ``C A_K^j = sum_a feat_a(lambda^j) tau[a]``."""
    vinv = np.linalg.inv(vec)
    keep, rows = [], []
    for i, li in enumerate(lam):
        t = np.outer(c @ vec[:, i], vinv[i])  # (l, n) complex
        if abs(li.imag) <= 1e-12 * max(1.0, abs(li)):
            keep.append(i)
            rows.append(t.real)
        elif li.imag > 0:
            keep.append(i)
            rows += [2.0 * t.real, -2.0 * t.imag]
    return keep, np.array(rows)


def refine_predictor(*, a_k: np.ndarray, c: np.ndarray,
                     flights: list[tuple[np.ndarray, np.ndarray]], feedthrough: bool
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """``B_K, D, K`` by one linear least-squares fit of the one-step predictor over all samples
    (:func:`predictor_fit` without the residuals)."""
    fit = predictor_fit(a_k=a_k, c=c, flights=flights, feedthrough=feedthrough)
    return None if fit is None else fit[:3]


class PredictorFit(NamedTuple):
    """:func:`predictor_fit`'s result: ``b_k (n, m)``, ``d (l, m)``, ``k (n, l)``, one
    ``x0 (n,)`` per flight, and the one-step errors ``y - yhat`` ``(N, l)`` of each flight
    (empty unless asked for)."""

    b_k: np.ndarray
    d: np.ndarray
    k: np.ndarray
    x0: list[np.ndarray]
    errors: list[np.ndarray]


def predictor_fit(*, a_k: np.ndarray, c: np.ndarray,
                  flights: list[tuple[np.ndarray, np.ndarray]], feedthrough: bool,
                  residuals: bool = False, k: np.ndarray | None = None
                  ) -> PredictorFit | None:
    """``B_K, D, K`` by one linear least-squares fit of the one-step predictor over all samples,
    and (``residuals=True``) the prediction errors ``y - yhat`` ``(N, l)`` of each flight.
    Given ``k`` ``(n, l)``, K is held at it and only ``B_K, D, x_0`` are fitted: the response
    to ``K y`` is subtracted from y and the features are the inputs' alone (``m n`` columns
    instead of ``(m + l) n``).

    With ``A_K = A - K C`` and C fixed, the predictor (thesis eq. 3.23's ``A_K, B_K``)

    .. math::

        \\hat y(k) = C A_K^k x_0 + \\sum_{t<k} C A_K^{k-1-t} (B_K u(t) + K y(t)) + D u(k)

    is linear in ``(B_K, K, D, x_0)`` (one ``x_0`` per flight). With
    ``A_K = V Lambda V^{-1}``, ``C A_K^j = sum_a f_a(lambda^j) tau_a`` with real modal
    features f (real part, and real/imaginary parts of one of each conjugate pair), so the
    regressors factor as (n features per channel of ``w = [u; y]``, from first-order
    ``lfilter`` runs) times ``tau``. The normal equations are then
    ``sum_l J_l^T (F^T F) J_l`` with ``F`` the ``(N, (m+l) n + m + n n_flights)`` feature
    matrix: one pass, ``O(N ((m+l) n)^2)``, no Python loop over samples. ``flights`` holds
    ``(u (N, m), y (N, l))`` in scaled units. Returns None when ``A_K`` is not safely
    diagonalisable (cond(V) > 1e8); the caller then keeps its estimates.
    """
    n, ell = a_k.shape[0], c.shape[0]
    m = flights[0][0].shape[1]
    held = k is not None  # K held: the K y response is known, only [u] channels are fitted
    cc = m if held else m + ell
    lam, vec = np.linalg.eig(a_k)
    if np.linalg.cond(vec) > 1e8:
        return None
    keep, tau = _modal_features(lam, vec, c)  # tau (n, l, n)
    n_fl = len(flights)
    n_bk, n_d = n * cc, (ell * m if feedthrough else 0)
    n_par = n_bk + n_d + n * n_fl
    n_feat = n_bk + n_d + n * n_fl
    gram = np.zeros((n_feat, n_feat))
    fty = np.zeros((n_feat, ell))
    feats, targets = [], []
    import scipy.signal  # where used: scipy.signal takes 0.5 s to import

    for f_idx, (u, y) in enumerate(flights):
        w = u if held else np.hstack([u, y])
        target = y - _held_response(lam, vec, c, k, y) if held else y
        feat = np.zeros((w.shape[0], n_feat))
        x0 = n_bk + n_d + n * f_idx
        col = 0  # feature j of channel ch is column ch * n + j; x0's feature j is x0 + j
        for i in keep:  # each mode's filter written straight into its columns (no copies)
            z = scipy.signal.lfilter([0.0, 1.0], [1.0, -lam[i]], w, axis=0)  # (N, cc)
            power = mode_power(lam[i], w.shape[0])  # 0 after its leading power.size rows
            for part in (np.real, np.imag) if lam[i].imag > 0 else (np.real,):
                feat[:, col:n_bk:n] = part(z)
                feat[:power.size, x0 + col] = part(power)
                col += 1
        if feedthrough:
            feat[:, n_bk:n_bk + m] = u
        gram += feat.T @ feat
        fty += feat.T @ target
        if residuals:
            feats.append(feat)
            targets.append(target)
    # J_l maps parameters to feature coefficients for output l
    lhs = np.zeros((n_par, n_par))
    rhs = np.zeros(n_par)
    jacs = []
    for out in range(ell):
        jac = np.zeros((n_feat, n_par))
        for ch in range(cc):
            jac[ch * n:(ch + 1) * n, ch * n:(ch + 1) * n] = tau[:, out, :]
        if feedthrough:
            jac[n_bk + np.arange(m), n_bk + out * m + np.arange(m)] = 1.0
        for f_idx in range(n_fl):
            x0 = n_bk + n_d + n * f_idx
            jac[x0:x0 + n, x0:x0 + n] = tau[:, out, :]
        lhs += jac.T @ gram @ jac
        rhs += jac.T @ fty[:, out]
        jacs.append(jac)
    theta = np.linalg.lstsq(lhs, rhs, rcond=None)[0]
    errs = []
    if residuals:
        coef = np.stack([jac @ theta for jac in jacs], axis=1)  # (n_feat, l)
        errs = [t - feat @ coef for feat, t in zip(feats, targets, strict=True)]
    # parameter index c * n + j is entry j of column c of [B_K, K] (of B_K alone when held)
    bk_all = theta[:n_bk].reshape(cc, n).T
    d = theta[n_bk:n_bk + n_d].reshape(ell, m) if feedthrough else np.zeros((ell, m))
    x0 = [theta[n_bk + n_d + n * f:n_bk + n_d + n * (f + 1)] for f in range(n_fl)]
    k_out = np.array(k, dtype=float) if held else bk_all[:, m:]
    return PredictorFit(bk_all[:, :m], d, k_out, x0, errs)


def _held_response(lam: np.ndarray, vec: np.ndarray, c: np.ndarray, k: np.ndarray,
                   y: np.ndarray) -> np.ndarray:
    """``(N, l)`` response of the predictor to ``K y`` alone, from rest:
    :math:`\\sum_{t<k} C A_K^{k-1-t} K y(t)`, by one first-order filter per mode of
    ``A_K = V Lambda V^{-1}``."""
    import scipy.signal

    r = y @ (np.linalg.solve(vec, k)).T  # (N, n) modal inputs V^-1 K y
    q = np.empty_like(r, dtype=complex)
    for i, li in enumerate(lam):
        q[:, i] = scipy.signal.lfilter([0.0, 1.0], [1.0, -li], r[:, i])
    return (q @ (c @ vec).T).real


def build_model(*, a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray,
                k: np.ndarray | None, noise_cov: np.ndarray | None, u_scale: np.ndarray,
                y_scale: np.ndarray, template: IOData, provenance: dict[str, Any],
                flights: Sequence[IOData] = ()) -> StateSpaceModel:
    """Undo the channel scaling and wrap the matrices with names, units and provenance.

    Scaled model: ``u_s = S_u^{-1} u``, ``y_s = S_y^{-1} y``; physical model
    ``B = B_s S_u^{-1}``, ``C = S_y C_s``, ``D = S_y D_s S_u^{-1}``, ``K = K_s S_y^{-1}``,
    noise covariance ``S_y Sigma_s S_y``. ``noise_cov`` ``(l, l)`` is the method's own estimate;
    with ``flights`` (the identification data, physical units, ``u (N_i, m)``, ``y (N_i, l)``)
    the model's ``noise_cov`` is that of its own one-step prediction errors on them
    (:func:`sysid.innovation_cov.own_noise_cov`).
    """
    su_inv = 1.0 / u_scale
    prov = dict(provenance)
    prov.setdefault("software", software_versions())
    prov["scaling"] = {"u_scale": u_scale.tolist(), "y_scale": y_scale.tolist(),
                       "note": "identification ran on channels divided by these; undone"}
    model = StateSpaceModel(
        A=a, B=b * su_inv, C=y_scale[:, None] * c, D=y_scale[:, None] * d * su_inv,
        K=None if k is None else k / y_scale, dt=template.dt,
        noise_cov=None if noise_cov is None else noise_cov * np.outer(y_scale, y_scale),
        input_names=template.input_names, output_names=template.output_names,
        input_units=template.input_units, output_units=template.output_units,
        provenance=prov)
    return own_noise_cov(model, flights=flights) if flights else model


@functools.cache
def _cached_versions() -> tuple[tuple[str, str], ...]:
    return tuple(_software_uncached().items())


def software_versions() -> dict[str, str]:
    """``{"cf-sysid": ..., "numpy": ..., "scipy": ...}``: versions for the provenance (looked
    up once: a metadata lookup costs milliseconds, which a grid of hundreds of models would pay
    every time)."""
    return dict(_cached_versions())


def _software_uncached() -> dict[str, str]:
    try:
        version = importlib.metadata.version("cf-sysid")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover - source checkout
        version = "unknown"
    return {"cf-sysid": version, "numpy": np.__version__, "scipy": scipy.__version__}
