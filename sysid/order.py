"""Model-order selection: singular values (thesis section 5.1.2, Figure 5.1), information
criteria (AIC, AICc, BIC) of the identified models, and a suggestion that says which rule gave
it (:func:`suggest_order`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from sysid.data import IOData, as_flights
from sysid.errors import ParameterError
from sysid.factor import build_products
from sysid.finish import check_flags
from sysid.kalman import stable_predictor
from sysid.methods import DEFAULT_METHOD, Method, get_method
from sysid.sweep import quiet_models
from sysid.validate import predict

__all__ = ["GAP_MIN_DECADES", "InformationCriteria", "OrderSuggestion", "information_criteria",
           "singular_values", "suggest_order"]


def singular_values(data: IOData | Sequence[IOData], *, past: int, future: int,
                    method: str | Method = DEFAULT_METHOD, feedthrough: bool | None = None,
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
    check_flags(scale=scale, **({} if feedthrough is None else {"feedthrough": feedthrough}))
    options = meth.sv_options(feedthrough=feedthrough, weighting=weighting)
    products = build_products(data, past=past, future=future, scale=scale)
    return meth.singular_values(products, options=options)


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
                         future: int, method: str | Method = DEFAULT_METHOD, **options: Any
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
        with quiet_models():  # a warning per order would flood the log
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


#: Smallest singular-value gap, decades (a factor of 2), that :func:`suggest_order` takes
#: as a clear cut between signal and noise.
GAP_MIN_DECADES = 0.3
#: A singular value at most this times the largest is zero (as in sysid.realize).
RANK_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class OrderSuggestion:
    """Result of :func:`suggest_order`: the suggested ``order``, the ``rule`` that gave it
    (``"gap"`` or ``"bic"``), what each rule picks (``by_rule``: ``gap``, ``aic``, ``aicc``,
    ``bic``), the gaps ``log10(s_n / s_n+1)`` looked at ``(k,)``, the largest in decades,
    whether it counts as clear, and ``reason`` (one line, for people)."""

    order: int
    rule: Literal["gap", "bic"]
    by_rule: dict[str, int]
    gaps: np.ndarray
    gap_decades: float
    gap_clear: bool
    reason: str


def suggest_order(sv: np.ndarray, ic: InformationCriteria, *, show: int | None = None,
                  max_order: int | None = None, min_gap: float = GAP_MIN_DECADES
                  ) -> OrderSuggestion:
    """An order from the singular values ``sv`` and the criteria ``ic``, saying which rule
    gave it.

    The gap rule picks the ``n`` maximising ``log10(s_n / s_n+1)`` among the first ``show``
    values, ``n <= max_order`` (the largest order the method identifies at these horizons,
    :meth:`sysid.methods.Method.max_order`). It is taken when it is clear: ``n >= 2`` and a
    gap of at least ``min_gap`` decades (a factor of 2). A largest gap right after the first
    value is degenerate (one dominant direction, e.g. the thrust's scale, says nothing about
    the order of the rest) and a smaller gap is no cut between signal and noise; the
    suggestion is then BIC's order (AIC over-fits long records). Validation on held-out data
    (:func:`sysid.auto.select`) is the better judge of either.
    """
    sv = np.asarray(sv, dtype=float)
    count = sv.size if show is None else min(show, sv.size)
    if max_order is not None:
        count = min(count, max_order + 1)
    head = sv[:count]
    # values after s_max_order that are zero: the rank cap of the horizons (p (m + l) rows
    # of the past), not a drop in the data; that step is no gap
    capped = (max_order is not None and head.size == max_order + 1
              and head[-1] <= RANK_TOL * head[0])
    if capped:
        head = head[:-1]
    with np.errstate(divide="ignore", invalid="ignore"):
        gaps = np.log10(head[:-1] / np.maximum(head[1:], 1e-300))
    gap_order = int(np.argmax(gaps)) + 1 if gaps.size else 1
    decades = float(gaps[gap_order - 1]) if gaps.size else 0.0
    clear = gap_order >= 2 and decades >= min_gap and not capped
    by_rule = {"gap": gap_order, **{k: int(v) for k, v in ic.chosen.items()}}
    bic = by_rule["bic"]
    edge = (" (the largest order scored: the best may lie beyond)"
            if bic == int(ic.orders[-1]) and ic.orders.size > 1 else "")
    if capped:
        why = (f"the singular values after s_{max_order} are zero because these horizons "
               f"allow at most {max_order} (the rank cap), not because of the data: the order "
               "may be higher; use a longer past")
        return OrderSuggestion(order=bic, rule="bic", by_rule=by_rule, gaps=gaps,
                               gap_decades=decades, gap_clear=False,
                               reason=f"BIC{edge}; gap rule not used: {why}")
    if clear:
        reason = (f"the singular values drop by {decades:.2f} decades after s_{gap_order}"
                  + ("" if bic == gap_order else f"; BIC picks {bic}{edge}"))
        return OrderSuggestion(order=gap_order, rule="gap", by_rule=by_rule, gaps=gaps,
                               gap_decades=decades, gap_clear=True, reason=reason)
    why = (f"the largest gap ({decades:.2f} decades) is right after s_1: one dominant "
           "direction, degenerate" if gap_order == 1 else
           f"the largest gap, after s_{gap_order}, is {decades:.2f} decades (< {min_gap:g}): "
           "no clear cut")
    return OrderSuggestion(order=bic, rule="bic", by_rule=by_rule, gaps=gaps,
                           gap_decades=decades, gap_clear=False,
                           reason=f"BIC{edge}; gap rule not used: {why}")
