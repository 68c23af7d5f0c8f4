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

import numpy as np

from sysid.data import IOData
from sysid.factor import DataProducts, build_products, triangular_factor
from sysid.model import StateSpaceModel
from sysid.realize import (
    ac_from_gamma,
    bd_thesis,
    build_model,
    check_order,
    gamma_from_svd,
    lstsq_coords,
)

__all__ = ["moesp_factor", "po_moesp"]

log = logging.getLogger(__name__)


def moesp_factor(products: DataProducts, *, factorization: str = "auto"
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``([L42 L43] (f l, p c), U_f coords (f m, r), Y_f coords (f l, r))`` from one LQ factor."""
    p, f = products.past, products.future
    pc = p * products.n_channels
    uf = np.concatenate([products.rows(block=p + i, kind="u") for i in range(f)])
    yf = np.concatenate([products.rows(block=p + i, kind="y") for i in range(f)])
    order = np.concatenate([uf, np.arange(pc), yf])
    low = triangular_factor(products, order, method=factorization)
    fm = uf.size
    l_yf = low[fm + pc:]
    return l_yf[:, fm:fm + pc], low[:fm], l_yf


def po_moesp(data: IOData | Sequence[IOData], *, order: int, past: int, future: int,
             feedthrough: bool = True, scale: bool = True, factorization: str = "auto"
             ) -> StateSpaceModel:
    """Identify ``(A, B, C, D)`` with PO-MOESP (open loop; biased under feedback).

    Args mirror :func:`sysid.iem`; ``feedthrough=True`` estimates D. Returns a model in
    physical units with ``K = 0``.
    """
    products = build_products(data, past=past, future=future, scale=scale)
    m, ell = products.n_inputs, products.n_outputs
    check_order(order=order, past=past, future=future, n_inputs=m, n_outputs=ell)
    l4, uf, yf = moesp_factor(products, factorization=factorization)
    gamma, sv = gamma_from_svd(l4 / np.sqrt(products.n_columns), order=order)
    a, c = ac_from_gamma(gamma, n_outputs=ell)
    b, d = bd_thesis(gamma=gamma, yf_uf_pinv=lstsq_coords(yf, uf), n_inputs=m,
                     n_outputs=ell, feedthrough=feedthrough)
    prov = {"method": "po-moesp", "order": order, "past": past, "future": future,
            "feedthrough": feedthrough, "n_flights": len(products.flights),
            "n_columns": products.n_columns,
            "n_samples": [fl.n_samples for fl in products.flights],
            "sources": [fl.source for fl in products.flights],
            "singular_values": sv.tolist(), "K": "not estimated (zero)"}
    return build_model(a=a, b=b, c=c, d=d, k=None, noise_cov=None, u_scale=products.u_scale,
                       y_scale=products.y_scale, template=products.flights[0],
                       provenance=prov)
