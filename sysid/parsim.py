"""PARSIM-K (Pannocchia and Calosi 2010; as SIPPY's ``PARSIM_K``), from the Gram of the data.

Closed-loop subspace identification in predictor form. With the past
:math:`Z_p = [U_p; Y_p]` and the future rows :math:`u_i, y_i` (``i = 0..f-1``), row 0 is the
regression :math:`y_0 \\approx \\Gamma_0 Z_p + H_0 u_0`; each later row removes what the earlier
ones explain and regresses the rest on :math:`R = [Z_p; u_0; y_0]`:

.. math::

    y_i - H_0 u_i - \\sum_{j=1}^{i-1} (H_j u_{i-j} + G_j y_{i-j})
    \\approx \\Gamma_i Z_p + H_i u_0 + G_i y_0 .

The stacked :math:`\\Gamma` ``(f l, p (m+l))`` is weighted by the past with the future inputs
projected out, :math:`W = (Z_p \\Pi^\\perp_{U_f} Z_p^T)^{1/2}`, and its SVD gives the predictor's
extended observability :math:`O_K = U_n S_n^{1/2}`: :math:`C` its first block row,
:math:`A_K` by shift invariance. :math:`B_K, D, K` (and one :math:`x_0` per flight) then come
from one least-squares fit of the one-step predictor (:func:`sysid.realize.predictor_fit`), and
:math:`A = A_K + K C`, :math:`B = B_K + K D`. With ``focus="simulation"`` B, D and x0 are
re-fitted by output error given A and C (as IEM and PO-MOESP do).

Every regression is a solve with blocks of the Gram matrix the other methods share
(:mod:`sysid.factor`), so the data are read once. On DaISy ``cstr`` (past = future = 20, D
estimated, order 10) it gives SIPPY 1.0.1's validation fit, 87.91 %
(``tests/sysid/test_parsim.py``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sysid.data import IOData
from sysid.errors import OrderError
from sysid.factor import DataProducts, check_exciting, given_products, triangular_factor
from sysid.finish import Focus, check_flags, check_focus
from sysid.model import StateSpaceModel
from sysid.output_error import output_error_bd
from sysid.pem import pem_refine
from sysid.realize import build_model, check_order, predictor_fit
from sysid.stability import Stability, check_stability, stabilize

__all__ = ["parsim_k", "parsim_k_singular_values"]


def _dependent(products: DataProducts) -> np.ndarray:
    """Which of the rows ``[Z_p; u_0; y_0]`` (the first ``p + 1`` blocks, canonical order)
    depend on the rows before them: the zero diagonal of their LQ factor
    (:func:`sysid.factor.triangular_factor`, judged on the data, not on the Gram, whose
    rounding hides the difference between noise-free data and a nearly collinear past)."""
    key = ("parsim-dependent",)
    if key not in products.cache:
        rows = np.arange((products.past + 1) * products.n_channels)
        products.cache[key] = np.diag(triangular_factor(products, rows)) == 0.0
    return products.cache[key]


def _solve(gram: np.ndarray, cols: np.ndarray, lhs: np.ndarray, dependent: np.ndarray
           ) -> np.ndarray:
    """``lhs @ pinv-solve(G[cols, cols])``: the least-squares coefficients on the rows
    ``cols`` of the signal whose cross-Gram with them is ``lhs``.

    ``dependent`` marks rows of ``cols`` that depend on the rows before them (noise-free data:
    y_0 is a function of Z_p and u_0). They get coefficient zero rather than a share of the
    minimum-norm solution: otherwise the output coefficients G_i would be arbitrary, and with
    them the predictor A_K. With y_0 dropped the predictor is the deterministic one, A_K = A
    and K = 0, which is exact."""
    g = gram[np.ix_(cols, cols)]
    if not dependent.any():
        return np.linalg.lstsq(g, lhs.T, rcond=None)[0].T
    keep = ~dependent
    theta = np.zeros((lhs.shape[0], cols.size))
    theta[:, keep] = np.linalg.lstsq(g[np.ix_(keep, keep)], lhs[:, keep].T, rcond=None)[0].T
    return theta


def _gamma(products: DataProducts) -> tuple[np.ndarray, np.ndarray]:
    """The weighted :math:`\\Gamma W` ``(f l, p (m+l))`` (module docstring) and its singular
    values, computed once per data products (``products.cache``: a sweep's orders at one
    pair of horizons share them; the order only truncates)."""
    key = ("parsim-gamma",)
    if key not in products.cache:
        products.cache[key] = _gamma_of(products)
    return products.cache[key]


def _gamma_of(products: DataProducts) -> tuple[np.ndarray, np.ndarray]:
    g = products.gram
    p, f = products.past, products.future
    pc = p * products.n_channels
    z = np.arange(pc)
    u = [products.rows(block=p + i, kind="u") for i in range(f)]
    y = [products.rows(block=p + i, kind="y") for i in range(f)]
    first = np.concatenate([z, u[0]])
    dependent = _dependent(products)  # over r = [Z_p; u_0; y_0]; `first` is its head
    theta = _solve(g, first, g[np.ix_(y[0], first)], dependent[:first.size])
    gammas, h, gk = [theta[:, :pc]], [theta[:, pc:]], [None]
    r = np.concatenate([z, u[0], y[0]])
    m = products.n_inputs
    for i in range(1, f):
        cross = g[np.ix_(y[i], r)] - h[0] @ g[np.ix_(u[i], r)]
        for j in range(1, i):
            cross = cross - h[j] @ g[np.ix_(u[i - j], r)] - gk[j] @ g[np.ix_(y[i - j], r)]
        theta = _solve(g, r, cross, dependent)
        gammas.append(theta[:, :pc])
        h.append(theta[:, pc:pc + m])
        gk.append(theta[:, pc + m:])
    uf = np.concatenate(u)
    s = g[np.ix_(z, z)] - g[np.ix_(z, uf)] @ np.linalg.lstsq(g[np.ix_(uf, uf)],
                                                            g[np.ix_(uf, z)], rcond=None)[0]
    w, v = np.linalg.eigh((s + s.T) / 2.0 / products.n_columns)
    weighted = np.vstack(gammas) @ (v * np.sqrt(np.clip(w, 0.0, None)))
    u_n, sv, _ = np.linalg.svd(weighted, full_matrices=False)
    return u_n * np.sqrt(sv), sv


def parsim_k_singular_values(products: DataProducts) -> np.ndarray:
    """The singular values of the weighted :math:`\\Gamma` (order selection)."""
    return _gamma(products)[1]


def parsim_k(data: IOData | Sequence[IOData] | None, *, order: int, past: int, future: int,
             feedthrough: bool = True, focus: Focus = "prediction",
             stability: Stability = "auto", scale: bool = True, pem: bool = False,
             products: DataProducts | None = None) -> StateSpaceModel:
    """Identify ``(A, B, C, D, K)`` with PARSIM-K (module docstring; closed loop).

    Args as :func:`sysid.iem`: ``data`` one or more flights (``u (N, m)``, ``y (N, l)``) or
    ``products`` built for ``past``/``future``; ``order`` states; ``feedthrough`` estimates D;
    ``focus`` "prediction" (the predictor fit, as SIPPY) or "simulation" (B, D, x0 by output
    error); ``stability`` as :mod:`sysid.stability`; ``pem`` then refines by prediction error
    with the criterion of ``focus``, as in :func:`sysid.iem`. Raises :class:`OrderError` when the
    predictor ``A_K`` is not safely diagonalisable (try another order).
    """
    check_focus(focus)
    check_stability(stability)
    check_flags(feedthrough=feedthrough, scale=scale, pem=pem)
    products = given_products(data, products=products, past=past, future=future, scale=scale)
    m, ell = products.n_inputs, products.n_outputs
    check_order(order=order, past=past, future=future, n_inputs=m, n_outputs=ell)
    check_exciting(products)  # over past + future, as IEM's and PO-MOESP's factors judge it
    ob, sv = _gamma(products)
    ob = ob[:, :order]
    a_k = np.linalg.lstsq(ob[:-ell], ob[ell:], rcond=None)[0]
    c = ob[:ell]
    flights = [(fl.u / products.u_scale, fl.y / products.y_scale) for fl in products.flights]
    radius = float(np.max(np.abs(np.linalg.eigvals(a_k))))
    if not radius < 1.0:  # the predictor fit needs a stable predictor; its regressors diverge
        raise OrderError(f"PARSIM-K: the predictor A_K of order {order} has a pole at |z| = "
                         f"{radius:.3g}; try a lower order or longer horizons")
    try:
        fit = predictor_fit(a_k=a_k, c=c, flights=flights, feedthrough=feedthrough,
                            residuals=True)
    except np.linalg.LinAlgError as exc:
        raise OrderError(f"PARSIM-K: the predictor fit of order {order} failed ({exc}); try "
                         "another order") from None
    if fit is None:
        raise OrderError(f"PARSIM-K: the predictor A_K of order {order} is not safely "
                             "diagonalisable; try another order")
    b_k, d, k, _, errors = fit
    a = a_k + k @ c
    a, moved = stabilize(a, mode=stability)
    b = b_k + k @ d
    e = np.vstack(errors)
    prov = {"method": "parsim-k", "order": order, "past": past, "future": future,
            "feedthrough": feedthrough, "focus": focus, "stability": stability,
            "n_flights": len(products.flights), "n_columns": products.n_columns,
            "n_samples": [fl.n_samples for fl in products.flights],
            "sources": [fl.source for fl in products.flights],
            "singular_values": sv.tolist(),
            "moved": [[abs(p0), abs(p1)] for p0, p1 in moved]}
    if focus == "simulation":
        b, d = output_error_bd(a=a, c=c, flights=flights, feedthrough=feedthrough)[:2]
    mats = (a, b, c, d, k, e.T @ e / e.shape[0])
    prov["pem"] = "off"
    if pem:
        mats, prov["pem"] = pem_refine(matrices=mats, flights=flights, feedthrough=feedthrough,
                                       criterion=focus)
    if moved:  # the report IEM gives (cli_identify prints it), the cost not measured here
        prov["stability"] = {
            "mode": stability, "measure": None, "fit_percent": None, "fit_percent_free": None,
            "cost_points": None,
            "moved": [{"from": [p0.real, p0.imag], "to": [p1.real, p1.imag],
                       "radius_from": abs(p0), "radius_to": abs(p1)} for p0, p1 in moved]}
    a, b, c, d, k, cov = mats
    return build_model(a=a, b=b, c=c, d=d, k=k, noise_cov=cov, u_scale=products.u_scale,
                       y_scale=products.y_scale, template=products.flights[0],
                       provenance=prov, flights=products.flights)
