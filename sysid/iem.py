"""Innovation Estimation Method (IEM, Qin & Ljung; thesis section 3.2 and Table 4.3).

Row i = 0..f-1 of the future (eq. 3.25/3.26; ``feedthrough=True`` adds the current input, the
``H_f1 U_1`` term of eq. 3.24):

.. math::

    Y_{f,i} = \\Gamma_{f,i} L_p Z_p + H^-_{f,i} U_{<i} + G^-_{f,i} \\hat E_{<i} + E_{f,i}

is solved by least squares (eq. 3.31) and its residual is the innovation estimate
:math:`\\hat E_{f,i}` (eqs. 3.28-3.30) used by the later rows. The stacked
:math:`\\widehat{\\Gamma_f L_p}` ``(f l, p (m+l))`` is reduced by an SVD (eq. 3.32).

**Fast path.** Each :math:`\\hat E_{f,j}` is :math:`Y_{f,j}` minus its projection on the
previous regressors, so ``span[Z_p, U_<i, Ê_<i] = span[Z_p, U_<i, Y_<i]``. Ordering the rows of
the joint Hankel matrix as ``[Z_p; y_0; u_0; y_1; u_1; ...]`` (``[Z_p; u_0; y_0; ...]`` with
feedthrough) makes every row regression "this block on all rows before it". One LQ factor
``W_perm = L Q^T`` (Cholesky of the Gram matrix, :mod:`sysid.factor`) then holds everything:
:math:`\\hat E_{f,i} = L_{ii} Q_i^T`, and the regressors ``[Z_p; U_<i; Ê_<i]`` have
coordinates ``M[:s_i, :s_i]``, where M is L with the off-diagonal part of each y-block row
zeroed (still lower triangular). So
:math:`[\\Gamma_{f,i} L_p, H^-, G^-] = L_{i,:s_i} M_{:s_i,:s_i}^{-1}` is one triangular solve,
with no second pass over the N samples. :func:`iem_direct` is the plain per-row ``lstsq``
version on the explicit arrays, kept as the reference.

**Departures from the thesis.** (1) The SVD is taken of
:math:`\\widehat{\\Gamma_f L_p} Z_p` (``weighting="data"``, the predicted future outputs,
invariant to how the past is scaled) rather than of :math:`\\widehat{\\Gamma_f L_p}` alone
(``weighting="none"``, eq. 3.32). (2) K comes from a regression on the estimated states
(``bk_method="state"``, see :mod:`sysid.realize`), and B, D from the one-step prediction error
(or, ``focus="simulation"``, the output error) with A, C, K held (:mod:`sysid.finish`); the
thesis' step 5 (``bk_method="thesis"``)
is biased under feedback and K then comes from the state regression with B, D fixed.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import logging
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from sysid.data import IOData, block_hankel
from sysid.errors import ParameterError
from sysid.factor import DataProducts, given_products, solve_right, triangular_factor
from sysid.finish import Finished, Focus, check_flags, check_focus, finish, stability_report
from sysid.model import StateSpaceModel
from sysid.pem import pem_refine
from sysid.realize import (
    Signals,
    bd_thesis,
    build_model,
    check_order,
    gamma_from_svd,
    lstsq_coords,
    refine_predictor,
)
from sysid.stability import Stability, check_stability, stabilize

__all__ = ["PREDICTABLE_INPUTS", "future_input_innovation", "iem", "iem_direct", "iem_order",
           "iem_signals", "realize_iem", "without_input_warning", "without_stability_cost"]

log = logging.getLogger(__name__)

#: Whether :func:`iem` measures the fit a moved pole cost (``provenance["stability"]``); off
#: inside :func:`without_stability_cost`.
_STABILITY_COST: contextvars.ContextVar[bool] = contextvars.ContextVar("iem_stability_cost",
                                                                       default=True)
#: Whether :func:`iem` warns of predictable future inputs; off inside
#: :func:`without_input_warning`.
_INPUT_WARNING: contextvars.ContextVar[bool] = contextvars.ContextVar("iem_input_warning",
                                                                     default=True)


@contextlib.contextmanager
def without_stability_cost() -> Iterator[None]:
    """Inside the block :func:`iem` does not measure what moving poles inside cost: the
    measurement identifies the model again with ``stability="free"`` (for the simulation focus
    another output-error fit over every sample) and runs both models over the identification
    data: on a long record most of the time of a sweep that scores its models and drops them
    (:mod:`sysid.sweep`). The model is the same; ``provenance["stability"]`` still
    lists the poles moved, with ``"measure": None`` and no cost. Models a sweep keeps
    (``keep_models``) are measured as usual."""
    token = _STABILITY_COST.set(False)
    try:
        yield
    finally:
        _STABILITY_COST.reset(token)

#: Below this share of their variance left unpredictable by the past (``Z_p``), the future
#: inputs make IEM's row regressions ill-conditioned: :func:`iem` warns. Measured at past
#: 20-30 (noise-free validation fit at the true order, IEM against PARSIM-K): the low-passed
#: inputs of ``bench select`` 6e-4 to 7e-4 (IEM 0.6 to 8e4 points worse), a 2x2 system under
#: inputs low-passed at 0.1 of Nyquist 4.4e-3 (80 against 99.5 %), DaISy robot_arm 1.2e-5
#: (IEM's prediction focus -47 to -459 % by the protocol, PARSIM-K 30-46 %), flutter 0 (IEM
#: unstable at every order). Above it the loss fades: CrazyPAD 0.016 (cmd_thrust; one-step
#: on log01 1-10 points below PARSIM-K), DaISy heating 0.021 and cstr 0.029 (no loss), demo
#: flights 0.28, PRBS 0.35-0.5, white inputs 0.8-1.
PREDICTABLE_INPUTS = 1e-2


def future_input_innovation(products: DataProducts) -> np.ndarray:
    """``(m,)``: the share of each first future input's variance that the past ``Z_p`` does
    not predict, :math:`1 - R^2` of ``u(k)`` regressed on ``z_p(k)``, from the Gram matrix
    (no pass over the data). Near 0 for low-passed, smooth or slowly held inputs, near 1 for
    white ones. Computed once per data products (``products.cache``)."""
    key = ("future-input-innovation",)
    if key not in products.cache:
        products.cache[key] = _innovation(products)
    return products.cache[key]


def _innovation(products: DataProducts) -> np.ndarray:
    g = products.gram
    z = np.arange(products.past * products.n_channels)
    u0 = products.rows(block=products.past, kind="u")
    g_zu = g[np.ix_(z, u0)]
    var = np.diag(g[np.ix_(u0, u0)])
    g_zz = g[np.ix_(z, z)]
    try:
        coef = np.linalg.solve(g_zz, g_zu)
    except np.linalg.LinAlgError:  # a dependent past (noise-free data)
        coef = np.linalg.lstsq(g_zz, g_zu, rcond=None)[0]
    explained = np.sum(g_zu * coef, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.clip(np.where(var > 0, 1.0 - explained / var, 1.0), 0.0, 1.0)


@contextlib.contextmanager
def without_input_warning() -> Iterator[None]:
    """Inside the block :func:`iem` does not warn of predictable future inputs (a selection
    that tries PARSIM-K beside IEM: the warning's advice is being followed)."""
    token = _INPUT_WARNING.set(False)
    try:
        yield
    finally:
        _INPUT_WARNING.reset(token)


_BK = ("state", "thesis")
_VARIANTS = {
    "consistent": {"bk_method": "state", "weighting": "data", "refine": False},
    "thesis": {"bk_method": "thesis", "weighting": "none", "refine": False},
}
_WEIGHTING = ("data", "none")


def iem_order(products: DataProducts, *, feedthrough: bool) -> np.ndarray:
    """Canonical row indices in IEM order: ``[Z_p; y_0; u_0; ...]`` or ``[Z_p; u_0; y_0; ...]``."""
    pc = products.past * products.n_channels
    parts = [np.arange(pc)]
    for i in range(products.future):
        u = products.rows(block=products.past + i, kind="u")
        y = products.rows(block=products.past + i, kind="y")
        parts += [u, y] if feedthrough else [y, u]
    return np.concatenate(parts)


def iem_signals(products: DataProducts, *, feedthrough: bool, factorization: str = "auto"
                ) -> tuple[np.ndarray, Signals]:
    """:math:`\\widehat{\\Gamma_f L_p}` ``(f l, p c)`` and the signals, from one LQ factor.

    The factor and :math:`\\widehat{\\Gamma_f L_p}` are taken from, or stored in,
    ``products.cache[("iem", feedthrough)]`` (with ``factorization="auto"``), so a horizon
    grid (:mod:`sysid.grid`) can hand every pair its share of one factorization.
    """
    order = iem_order(products, feedthrough=feedthrough)
    key = ("iem", bool(feedthrough))
    cached = products.cache.get(key) if factorization == "auto" else None
    low, cached_gamma = cached if cached is not None else (
        triangular_factor(products, order, method=factorization), None)
    pos = np.empty_like(order)
    pos[order] = np.arange(order.size)
    p, f, ell = products.past, products.future, products.n_outputs
    pc = p * products.n_channels
    y_pos = [pos[products.rows(block=p + i, kind="y")] for i in range(f)]
    coords = low.copy()  # M: rows of Ê_j reduced to their diagonal block
    for yp in y_pos:
        diag = low[np.ix_(yp, yp)]
        coords[yp] = 0.0
        coords[np.ix_(yp, yp)] = diag
    gamma_lp = cached_gamma
    if gamma_lp is None:
        gamma_lp = np.empty((f * ell, pc))
        for i, yp in enumerate(y_pos):
            s = yp[0]
            theta = solve_right(coords[:s, :s], low[yp, :s])
            gamma_lp[i * ell:(i + 1) * ell] = theta[:, :pc]
        if factorization == "auto":
            products.cache[key] = (low, gamma_lp)

    def rows(idx: np.ndarray) -> np.ndarray:
        return low[pos[idx]]

    all_u = np.concatenate([products.rows(block=p + i, kind="u") for i in range(f)])
    all_y = np.concatenate([products.rows(block=p + i, kind="y") for i in range(f)])
    sig = Signals(zp=low[:pc], zp_next=rows(np.arange(products.n_channels, pc +
                                                      products.n_channels)),
                  u0=rows(products.rows(block=p, kind="u")),
                  y0=rows(products.rows(block=p, kind="y")), e0=coords[y_pos[0]],
                  uf=rows(all_u), yf=rows(all_y), n_columns=products.n_columns)
    return gamma_lp, sig


def iem_direct(products: DataProducts, *, feedthrough: bool) -> tuple[np.ndarray, Signals]:
    """Reference: the same as :func:`iem_signals` by per-row ``lstsq`` on the explicit arrays.

    O(f N r^2): slow (the baseline of ``bench/bench_sysid.py``) but obviously right.
    """
    blocks = products.past + products.future
    w = np.hstack([block_hankel(products.scaled_w(d), block_rows=blocks)
                   for d in products.flights if d.n_samples >= blocks])
    p, f, c, ell = products.past, products.future, products.n_channels, products.n_outputs
    zp = w[: p * c]
    gamma_lp = np.empty((f * ell, p * c))
    us = [w[products.rows(block=p + i, kind="u")] for i in range(f)]
    ys = [w[products.rows(block=p + i, kind="y")] for i in range(f)]
    es: list[np.ndarray] = []
    for i in range(f):
        reg = [zp]
        for j in range(i + 1 if feedthrough else i):
            reg.append(us[j])
        reg += es
        reg_m = np.vstack(reg)
        theta = lstsq_coords(ys[i], reg_m)
        gamma_lp[i * ell:(i + 1) * ell] = theta[:, : p * c]
        es.append(ys[i] - theta @ reg_m)
    sig = Signals(zp=zp, zp_next=w[c:(p + 1) * c], u0=us[0], y0=ys[0], e0=es[0],
                  uf=np.vstack(us), yf=np.vstack(ys), n_columns=products.n_columns)
    return gamma_lp, sig


def realize_iem(gamma_lp: np.ndarray, sig: Signals, *, order: int, n_outputs: int,
                feedthrough: bool, bk_method: str, weighting: str,
                flights: list[tuple[np.ndarray, np.ndarray]], focus: Focus = "prediction",
                stability: Stability = "auto", refine: bool = False,
                svd_cache: dict[Any, Any] | None = None) -> tuple[Finished, np.ndarray, str]:
    """The model in scaled units (:class:`sysid.finish.Finished`), the singular values of
    step 3, and what the predictor refinement did ("off", "done" or why it was skipped).

    ``flights``: the scaled ``(u, y)`` of each flight (output error, refinement). With
    ``refine`` (prediction focus only) ``(A, B, D, K)`` are refitted with
    :func:`sysid.realize.refine_predictor` (A = A_K + K C, B = B_K + K D; C and A_K kept); the
    refinement is dropped when it would leave A with poles the stability mode moves.
    ``svd_cache`` (the products' cache) keeps the SVD for the other orders of the pair.
    """
    key = ("iem-svd", weighting, feedthrough)
    o = None if svd_cache is not None and key in svd_cache else (
        gamma_lp @ sig.zp / np.sqrt(sig.n_columns) if weighting == "data" else gamma_lp)
    gamma, sv = gamma_from_svd(o, order=order, cache=svd_cache, key=key)
    bd = None
    if bk_method == "thesis":
        bd = bd_thesis(gamma=gamma, yf_uf_pinv=lstsq_coords(sig.yf, sig.uf),
                       n_inputs=sig.u0.shape[0], n_outputs=n_outputs, feedthrough=feedthrough)
    fin = finish(gamma=gamma, gamma_lp=gamma_lp, sig=sig, feedthrough=feedthrough, focus=focus,
                 stability=stability, flights=flights, bd=bd)
    if not refine:
        return fin, sv, "off"
    if focus != "prediction":
        return fin, sv, "skipped: refinement fits the predictor (focus='prediction')"
    a_k = fin.a - fin.k @ fin.c
    if np.max(np.abs(np.linalg.eigvals(a_k))) >= 0.999:
        log.warning("IEM refinement skipped: the predictor A - K C is unstable")
        return fin, sv, "skipped: predictor A - K C unstable"
    refined = refine_predictor(a_k=a_k, c=fin.c, flights=flights, feedthrough=feedthrough)
    if refined is None:
        return fin, sv, "skipped: A - K C not diagonalisable"
    b_k, d, k = refined
    a_new = a_k + k @ fin.c
    if stabilize(a_new, mode=stability)[1]:
        log.info("IEM refinement dropped: it moves poles outside the unit circle")
        return fin, sv, "dropped: the refined A has poles outside the unit circle"
    return dataclasses.replace(fin, a=a_new, b=b_k + k @ d, d=d, k=k), sv, "done"


def iem(data: IOData | Sequence[IOData], *, order: int, past: int, future: int,
        feedthrough: bool = False, variant: str = "consistent", focus: Focus = "prediction",
        stability: Stability = "auto", bk_method: str | None = None,
        weighting: str | None = None, scale: bool = True, factorization: str = "auto",
        direct: bool = False, refine: bool | None = None, pem: bool = False,
        products: DataProducts | None = None) -> StateSpaceModel:
    """Identify an innovation-form model with IEM from one flight or a list of flights.

    Args:
        data: ``IOData`` (u ``(N, m)``, y ``(N, l)``) or a list of them (each its own columns).
        order: model order n. past, future: horizons p, f in samples.
        feedthrough: estimate D (and use the current input in the row regressions); False
            means D = 0, right for a loop without delay (u(k) already reacts to y(k)).
        variant: a preset for the choices below. "consistent" (default): K from the state
            regression and B, D as ``focus`` says, data weighting, no refinement. "thesis":
            Table 4.3 exactly (thesis B/D from eq. 3.15, no weighting), for reproducing the
            thesis; biased in closed loop. Arguments given explicitly override the preset.
        focus: "prediction" (default): K from the closed-loop-consistent state
            regression, then B, D and x0 by least squares on the one-step prediction error
            with A, C, K held; the right choice for flight data and k-step prediction.
            "simulation": B, D and x0 re-estimated by output error with A, C (and K) from the
            subspace step; for open-loop data with colored inputs; biased under feedback
            (:mod:`sysid.finish`, ``docs/sysid.md``).
        stability: "auto" (default), "enforce" or "free" (:mod:`sysid.stability`): "auto"
            moves poles just outside the unit circle (|z| <= 1.1) inside: to 0.999 near z = 1
            (an integrator's estimate), reflected elsewhere; "enforce" puts every pole
            strictly inside (MATLAB's EnforceStability);
            B, D, K are estimated for the final A and the fit it cost is in
            ``provenance["stability"]``.
        bk_method: "state" (closed-loop consistent) or "thesis" (eq. 3.15).
        weighting: "data" (SVD of Γ_f L_p Z_p) or "none" (thesis eq. 3.32).
        scale: divide channels by their std inside the identification (undone in the model).
        factorization: "auto", "cholesky" or "qr" (see :func:`sysid.factor.triangular_factor`).
        direct: use the per-row ``lstsq`` reference path instead of the fast one.
        refine: one linear least-squares fit of the one-step predictor over all samples
            (:func:`sysid.realize.refine_predictor`; it re-estimates A as A_K + K C). Off by
            default: on the project's closed-loop flights it raises the one-step fit a little
            and costs windowed-simulation fit and stability (``docs/sysid.md``).
        pem: then refine by prediction error (:mod:`sysid.pem`) with the criterion of
            ``focus``: one-step prediction errors over ``A_K``, C, or simulation errors over A,
            C (an output-error model, K = 0); the IEM model is kept (and provenance["pem"]
            says why) if the cost does not decrease.
        products: the data products of ``data`` for these horizons, already built
            (:func:`sysid.factor.build_products`, or a pair of :mod:`sysid.grid`, whose cache
            holds a shared factor); ``data`` is then not read again.

    Returns:
        ``StateSpaceModel`` in physical units with K and the innovation covariance.
    """
    if variant not in _VARIANTS:
        raise ParameterError(f"variant={variant!r}; use one of {tuple(_VARIANTS)}")
    check_focus(focus)
    check_stability(stability)
    check_flags(feedthrough=feedthrough, scale=scale, direct=direct, pem=pem,
                **({} if refine is None else {"refine": refine}))
    preset = _VARIANTS[variant]
    bk_method = preset["bk_method"] if bk_method is None else bk_method
    weighting = preset["weighting"] if weighting is None else weighting
    refine = bool(preset["refine"] if refine is None else refine)
    if bk_method not in _BK:
        raise ParameterError(f"bk_method={bk_method!r}; use one of {_BK}")
    if weighting not in _WEIGHTING:
        raise ParameterError(f"weighting={weighting!r}; use one of {_WEIGHTING}")
    if bk_method == "thesis" and focus == "simulation":
        raise ParameterError("focus='simulation' re-estimates B, D by output error; the "
                             "thesis' B, D (eq. 3.15) go with focus='prediction'")
    products = given_products(data, products=products, past=past, future=future, scale=scale)
    m, ell = products.n_inputs, products.n_outputs
    check_order(order=order, past=past, future=future, n_inputs=m, n_outputs=ell)
    innovation = float(np.min(future_input_innovation(products), initial=1.0))
    if innovation < PREDICTABLE_INPUTS and _INPUT_WARNING.get():
        log.warning("IEM: the past predicts the future inputs to within %.2g of their variance "
                    "(low-passed or slowly varying inputs): IEM's row regressions cannot tell "
                    "their terms from the past's, and its model can be far off; PARSIM-K "
                    "(method 'parsim-k') fixes those terms' causal structure, and no knobs "
                    "(sysid identify without --method) tries it", innovation)
    if direct:
        gamma_lp, sig = iem_direct(products, feedthrough=feedthrough)
    else:
        gamma_lp, sig = iem_signals(products, feedthrough=feedthrough,
                                    factorization=factorization)
    flights = [(fl.u / products.u_scale, fl.y / products.y_scale) for fl in products.flights]
    common = {"order": order, "n_outputs": ell, "feedthrough": feedthrough,
              "bk_method": bk_method, "weighting": weighting, "flights": flights,
              "focus": focus, "refine": refine,
              "svd_cache": None if direct else products.cache}
    fin, sv, status = realize_iem(gamma_lp, sig, stability=stability, **common)
    pem_status = "off"
    mats = (fin.a, fin.b, fin.c, fin.d, fin.k, fin.noise_cov)
    if pem:
        mats, pem_status = pem_refine(matrices=mats, flights=flights, feedthrough=feedthrough,
                                      criterion=focus)
    prov = {"method": "iem", "order": order, "past": past, "future": future,
            "feedthrough": feedthrough, "variant": variant, "focus": focus,
            "stability": stability, "bk_method": bk_method, "weighting": weighting,
            "n_flights": len(products.flights), "n_columns": products.n_columns,
            "n_samples": [fl.n_samples for fl in products.flights],
            "sources": [fl.source for fl in products.flights],
            "singular_values": sv.tolist(), "path": "direct" if direct else "fast",
            "refine": status, "pem": pem_status, "estimates": fin.notes,
            "future_input_innovation": innovation}
    a, b, c, d, k, cov = mats
    model = build_model(a=a, b=b, c=c, d=d, k=k, noise_cov=cov, u_scale=products.u_scale,
                        y_scale=products.y_scale, template=products.flights[0],
                        provenance=prov, flights=products.flights)
    if fin.moved and _STABILITY_COST.get():
        free, _, _ = realize_iem(gamma_lp, sig, stability="free", **common)
        model = stability_report(model=model, fin=fin, free=free, products=products)
    elif fin.moved:  # the poles moved, their cost not measured (without_stability_cost)
        model = model.replace(provenance={**model.provenance, "stability": {
            "mode": stability,
            "moved": [{"from": [p.real, p.imag], "to": [q.real, q.imag], "radius_from": abs(p),
                       "radius_to": abs(q)} for p, q in fin.moved],
            "measure": None, "fit_percent": None, "fit_percent_free": None,
            "cost_points": None}})
    return model
