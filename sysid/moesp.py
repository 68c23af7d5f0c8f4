"""PO-MOESP (Verhaegen; thesis section 3.1), an open-loop method kept for comparison.

LQ factorization (eq. 3.16) of ``[U_f; U_p; Y_p; Y_f]`` (here ``[U_f; Z_p; Y_f]``, the same
span), range of ``[L42 L43]`` = range of :math:`\\Gamma_f` (eq. 3.17), order reduction by SVD
(eqs. 3.9-3.10), A and C by shift invariance (eqs. 3.11-3.12), B and D from
:math:`\\Gamma_f^\\perp Y_f U_f^\\dagger = \\Gamma_f^\\perp H_f` (eqs. 3.13-3.15). With
``feedthrough=False`` D = 0 is imposed. The LQ factor comes from the same Gram matrix as IEM
(:mod:`sysid.factor`), so there is no second pass over the samples. In closed loop the inputs
are correlated with the past noise (Assumption 4 fails) and the estimates are biased; K is not
estimated (zero) and the noise covariance is left unknown.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import Literal

import numpy as np

from sysid.data import IOData
from sysid.errors import ParameterError
from sysid.factor import DataProducts, given_products, solve_right, triangular_factor
from sysid.finish import Finished, Focus, check_flags, check_focus, finish, stability_report
from sysid.model import StateSpaceModel
from sysid.pem import pem_refine
from sysid.realize import (
    Signals,
    ac_from_gamma,
    bd_thesis,
    build_model,
    check_order,
    gamma_from_svd,
    lstsq_coords,
)
from sysid.stability import Stability, check_stability, stabilize

__all__ = ["moesp_factor", "moesp_signals", "po_moesp"]

log = logging.getLogger(__name__)


def moesp_factor(products: DataProducts, *, factorization: str = "auto"
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``([L42 L43] (f l, p c), U_f coords (f m, r), Y_f coords (f l, r))`` from one LQ factor."""
    l4, _, sig = moesp_signals(products, factorization=factorization)
    return l4, sig.uf, sig.yf


def moesp_signals(products: DataProducts, *, factorization: str = "auto"
                  ) -> tuple[np.ndarray, np.ndarray, Signals]:
    r"""``[L42 L43] (f l, p c)``, the oblique projection map ``Γ_f L_p (f l, p c)`` and the row
    signals in the coordinates of the LQ factor of ``[U_f; Z_p; Y_f]``.

    With ``W = L Q^T``: ``Y_f = L_yu Q_u + L_yz Q_z + L_yy Q_y`` and
    ``Z_p = L_zu Q_u + L_zz Q_z``, so the oblique projection of ``Y_f`` along ``U_f`` onto
    ``Z_p`` is :math:`L_{yz} L_{zz}^{-1} Z_p`: the map from the past to the state part of the
    future outputs, :math:`\widehat{\Gamma_f L_p}`, as IEM's row regressions give it.
    Kept in ``products.cache`` for the other orders of the same products.
    """
    key = ("moesp", factorization)
    if key not in products.cache:
        products.cache[key] = _moesp_signals(products, factorization=factorization)
    return products.cache[key]


def _moesp_signals(products: DataProducts, *, factorization: str
                   ) -> tuple[np.ndarray, np.ndarray, Signals]:
    p, f = products.past, products.future
    c = products.n_channels
    pc = p * c
    uf = np.concatenate([products.rows(block=p + i, kind="u") for i in range(f)])
    yf = np.concatenate([products.rows(block=p + i, kind="y") for i in range(f)])
    order = np.concatenate([uf, np.arange(pc), yf])
    low = triangular_factor(products, order, method=factorization)
    pos = np.empty_like(order)
    pos[order] = np.arange(order.size)
    fm = uf.size
    l_yf = low[fm + pc:]
    l_zz = low[fm:fm + pc, fm:fm + pc]
    gamma_lp = solve_right(l_zz, l_yf[:, fm:fm + pc])

    def rows(idx: np.ndarray) -> np.ndarray:
        return low[pos[idx]]

    zp = low[fm:fm + pc]
    u0 = rows(products.rows(block=p, kind="u"))
    y0 = rows(products.rows(block=p, kind="y"))
    e0 = y0 - lstsq_coords(y0, np.vstack([zp, u0])) @ np.vstack([zp, u0])
    sig = Signals(zp=zp, zp_next=rows(np.arange(c, pc + c)), u0=u0, y0=y0, e0=e0,
                  uf=low[:fm], yf=l_yf, n_columns=products.n_columns)
    return l_yf[:, fm:fm + pc], gamma_lp, sig


def po_moesp(data: IOData | Sequence[IOData], *, order: int, past: int, future: int,
             feedthrough: bool = True, variant: Literal["standard", "thesis"] = "standard",
             focus: Focus = "simulation", stability: Stability = "auto", scale: bool = True,
             factorization: str = "auto", pem: bool = False,
             products: DataProducts | None = None) -> StateSpaceModel:
    r"""Identify ``(A, B, C, D)`` with PO-MOESP (open loop; biased under feedback).

    Args mirror :func:`sysid.iem` (``products=`` too); ``feedthrough=True`` estimates D.

    Args:
        variant: "standard" (default): B, D as ``focus`` says. "thesis": B, D from
            :math:`\Gamma^\perp Y_f U_f^\dagger` (eq. 3.15), exact for white inputs and
            noise-free data but it amplifies the error of :math:`\Gamma^\perp` when the input
            is colored (a validation fit of -18 000 % on DaISy ``CD_player_arm``); K = 0.
        focus: "simulation" (default, as MATLAB ``n4sid`` with simulation focus): B, D and x0
            by least squares on the output error given A and C; K from the state regression.
            "prediction": K by regression on the states of the oblique projection (N4SID
            style), then B, D and x0 by the one-step prediction error with A, C, K held.
        stability: as in :func:`sysid.iem` (:mod:`sysid.stability`).
        pem: then refine by prediction error with the criterion of ``focus``, as in
            :func:`sysid.iem` (simulation: an output-error model, K = 0).

    Returns a model in physical units; ``provenance["x0"]`` holds the initial state of each
    flight (simulation focus).
    """
    if variant not in ("standard", "thesis"):
        raise ParameterError(f"variant={variant!r}; use 'standard' or 'thesis'")
    check_focus(focus)
    check_stability(stability)
    check_flags(feedthrough=feedthrough, scale=scale, pem=pem)
    products = given_products(data, products=products, past=past, future=future, scale=scale)
    m, ell = products.n_inputs, products.n_outputs
    check_order(order=order, past=past, future=future, n_inputs=m, n_outputs=ell)
    l4, gamma_lp, sig = moesp_signals(products, factorization=factorization)
    gamma, sv = gamma_from_svd(l4 / np.sqrt(products.n_columns), order=order,
                               cache=products.cache, key="moesp-svd")
    flights = [(fl.u / products.u_scale, fl.y / products.y_scale) for fl in products.flights]
    prov = {"method": "po-moesp", "order": order, "past": past, "future": future,
            "feedthrough": feedthrough, "variant": variant, "focus": focus,
            "stability": stability, "n_flights": len(products.flights),
            "n_columns": products.n_columns,
            "n_samples": [fl.n_samples for fl in products.flights],
            "sources": [fl.source for fl in products.flights],
            "singular_values": sv.tolist()}
    if variant == "thesis":
        a, c = ac_from_gamma(gamma, n_outputs=ell)
        a, moved = stabilize(a, mode=stability)
        b, d = bd_thesis(gamma=gamma, yf_uf_pinv=lstsq_coords(sig.yf, sig.uf), n_inputs=m,
                         n_outputs=ell, feedthrough=feedthrough)
        prov.update(K="not estimated (zero)", focus="thesis eq. 3.15",
                    moved=[[abs(p0), abs(p1)] for p0, p1 in moved])
        return build_model(a=a, b=b, c=c, d=d, k=None, noise_cov=None,
                           u_scale=products.u_scale, y_scale=products.y_scale,
                           template=products.flights[0], provenance=prov,
                           flights=products.flights)

    def realize(mode: Stability) -> Finished:
        return finish(gamma=gamma, gamma_lp=gamma_lp, sig=sig, feedthrough=feedthrough,
                      focus=focus, stability=mode, flights=flights)

    fin = realize(stability)
    prov["estimates"] = fin.notes
    prov["x0"] = [x.tolist() for x in fin.x0]
    mats = (fin.a, fin.b, fin.c, fin.d, fin.k, fin.noise_cov)
    prov["pem"] = "off"
    if pem:
        mats, prov["pem"] = pem_refine(matrices=mats, flights=flights, feedthrough=feedthrough,
                                       criterion=focus)
    a, b, c, d, k, cov = mats
    model = build_model(a=a, b=b, c=c, d=d, k=k, noise_cov=cov,
                        u_scale=products.u_scale, y_scale=products.y_scale,
                        template=products.flights[0], provenance=prov,
                        flights=products.flights)
    if fin.moved:
        model = stability_report(model=model, fin=fin, free=realize("free"), products=products)
    return model
