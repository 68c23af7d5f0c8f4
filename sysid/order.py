"""Model-order selection: singular values (thesis section 5.1.2, Figure 5.1) and information
criteria (AIC, AICc, BIC) of the identified models."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from sysid.data import IOData, as_flights
from sysid.errors import ParameterError
from sysid.factor import build_products
from sysid.methods import Method, get_method
from sysid.validate import predict, stable_predictor

__all__ = ["InformationCriteria", "information_criteria", "singular_values"]


def singular_values(data: IOData | Sequence[IOData], *, past: int, future: int,
                    method: str | Method = "iem", feedthrough: bool | None = None,
                    weighting: Literal["data", "none"] = "data", scale: bool = True
                    ) -> np.ndarray:
    """Singular values ``(min(f l, p (m+l)),)`` of the matrix whose SVD sets the order.

    IEM: :math:`\\widehat{\\Gamma_f L_p} Z_p / \\sqrt{M}` (``weighting="data"``) or
    :math:`\\widehat{\\Gamma_f L_p}` (``"none"``, eq. 3.32); PO-MOESP: ``[L42 L43] / sqrt(M)``
    (eq. 3.17). ``M`` is the number of Hankel columns, so values do not grow with N.
    ``method`` is a name of :data:`sysid.methods.METHODS` (``"po_moesp"`` works too).
    ``feedthrough`` defaults to the method's own default (False for IEM, True for PO-MOESP).
    The same values are stored in ``model.provenance["singular_values"]``.
    """
    meth = get_method(method)
    kwargs: dict[str, object] = {} if feedthrough is None else {"feedthrough": feedthrough}
    if meth.name == "iem":
        kwargs["weighting"] = weighting
    products = build_products(data, past=past, future=future, scale=scale)
    return meth.singular_values(products, options=meth.options(**kwargs))


@dataclass(frozen=True, eq=False)
class InformationCriteria:
    """Result of :func:`information_criteria`: one entry per order, arrays ``(n_orders,)``.

    ``log_det`` is :math:`\\log\\det\\hat\\Sigma` of the one-step prediction errors,
    ``n_params`` the count ``d`` used, ``n_samples`` the total ``N``; ``chosen`` maps
    ``"aic"``, ``"aicc"``, ``"bic"`` to the order with the smallest value.
    """

    orders: np.ndarray
    n_params: np.ndarray
    log_det: np.ndarray
    aic: np.ndarray
    aicc: np.ndarray
    bic: np.ndarray
    n_samples: int
    chosen: dict[str, int]


def information_criteria(data: IOData | Sequence[IOData], *, orders: Sequence[int], past: int,
                         future: int, method: str = "iem", **options: Any
                         ) -> InformationCriteria:
    """AIC, AICc and BIC (MDL) per order of the ``method`` model on its identification data.

    Each order is identified with ``past``/``future`` and ``options`` (those of the method,
    e.g. ``focus``, ``feedthrough``) from one shared set of data products. With the
    covariance :math:`\\hat\\Sigma = \\frac1N \\sum_t \\varepsilon(t)\\varepsilon(t)^T` of the
    one-step prediction errors over all ``N`` samples of all flights, ``l`` outputs and ``d``
    parameters (MATLAB's definitions, the constant included):

    * ``AIC  = N log det Σ + 2 d + N l (log 2π + 1)``
    * ``AICc = AIC + 2 d (d + 1) / (N - d - 1)``
    * ``BIC  = N log det Σ + d log N + N l (log 2π + 1)`` (Rissanen's MDL is BIC / 2).

    ``d`` counts the innovation form :math:`(A, B, C, D, K)` up to a change of state basis:
    ``n (2 l + m)`` for A, B, C, K (``n² + n m + l n + n l`` minus the ``n²`` of the basis),
    plus ``l m`` if D is estimated (``feedthrough``), plus ``n`` per flight for the initial
    state the predictor estimates. A model whose predictor ``A - KC`` is unstable is scored
    with its steady-state Kalman gain (:func:`sysid.stable_predictor`).
    """
    meth = get_method(method)
    opts = meth.options(**options)
    flights = as_flights(data)
    orders = sorted({int(n) for n in orders})
    if not orders or orders[0] < 1:
        raise ParameterError(f"orders={orders!r}; pass positive model orders")
    products = build_products(flights, past=past, future=future, scale=True)
    m, ell = flights[0].n_inputs, flights[0].n_outputs
    n_total = sum(d.n_samples for d in flights)
    log_det, n_params = [], []
    for n in orders:
        model = meth.identify(flights, order=n, past=past, future=future, options=opts,
                              products=products)
        if not model.predictor_is_stable:
            model = stable_predictor(model)
        with np.errstate(over="ignore", invalid="ignore"):
            err = np.vstack([d.y - predict(model, u=d.u, y=d.y, horizon=1)[0] for d in flights])
        cov = err.T @ err / n_total
        sign, ld = np.linalg.slogdet(cov) if np.isfinite(cov).all() else (0.0, np.inf)
        log_det.append(ld if sign > 0 else np.inf)
        feed = bool(getattr(opts, "feedthrough", False))
        n_params.append(n * (2 * ell + m) + (ell * m if feed else 0) + n * len(flights))
    ld_arr, d_arr = np.array(log_det), np.array(n_params, dtype=float)
    const = n_total * ell * (np.log(2 * np.pi) + 1)
    aic = n_total * ld_arr + 2 * d_arr + const
    with np.errstate(divide="ignore"):
        corr = np.where(n_total - d_arr - 1 > 0, 2 * d_arr * (d_arr + 1) / (n_total - d_arr - 1),
                        np.inf)
    bic = n_total * ld_arr + d_arr * np.log(n_total) + const
    crit = {"aic": aic, "aicc": aic + corr, "bic": bic}
    return InformationCriteria(
        orders=np.array(orders), n_params=d_arr.astype(int), log_det=ld_arr, aic=aic,
        aicc=crit["aicc"], bic=bic, n_samples=n_total,
        chosen={k: orders[int(np.argmin(v))] for k, v in crit.items()})
