"""Model-order selection: singular values (thesis section 5.1.2, Figure 5.1), information
criteria (AIC, AICc, BIC) of the identified models, and a suggestion that says which rule gave
it (:func:`suggest_order`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from sysid.data import IOData, as_flights
from sysid.errors import OrderError, ParameterError, SysIdError, first_line
from sysid.factor import build_products
from sysid.finish import check_flags
from sysid.innovation_cov import without_own_noise_cov
from sysid.kalman import error_covariance, one_step_errors
from sysid.methods import DEFAULT_METHOD, Method, get_method
from sysid.sweep import quiet_models

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

    ``orders`` are the orders asked for, ascending; ``log_det`` is
    :math:`\\log\\det\\hat\\Sigma` of the one-step prediction errors, ``aic``, ``aicc``,
    ``bic`` the criteria, ``n_params`` the count ``d`` (defined for every order), ``n_samples``
    the total ``N``. ``failed`` maps each order the method could not identify to its one-line
    reason (e.g. PARSIM-K's unstable predictor); such an order holds NaN in ``log_det``,
    ``aic``, ``aicc`` and ``bic``. ``chosen`` maps ``"aic"``, ``"aicc"``, ``"bic"`` to the
    order with the smallest value among the orders that did not fail.
    """

    orders: np.ndarray
    n_params: np.ndarray
    log_det: np.ndarray
    aic: np.ndarray
    aicc: np.ndarray
    bic: np.ndarray
    n_samples: int
    chosen: dict[str, int]
    failed: dict[int, str] = field(default_factory=dict)

    @property
    def scored(self) -> np.ndarray:
        """The orders that were identified and scored (``orders`` without ``failed``)."""
        return np.array([n for n in self.orders if int(n) not in self.failed], dtype=int)


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

    An order the method cannot identify (a :class:`SysIdError`, e.g. PARSIM-K's predictor
    ``A_K`` with a pole outside the unit circle) does not end the call: it is listed in
    ``failed`` with its reason and holds NaN, and ``chosen`` ignores it. When every order
    fails, :class:`OrderError` says so in one line with the first three orders' reasons.
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
    feed = bool(getattr(opts, "feedthrough", False))
    log_det, failed = [], {}
    for n in orders:
        try:
            log_det.append(_log_det(meth, flights, order=n, past=past, future=future,
                                    options=opts, products=products))
        except (SysIdError, np.linalg.LinAlgError) as exc:
            failed[n] = first_line(exc)
            log_det.append(np.nan)
    if len(failed) == len(orders):
        reasons = [f"order {n}: {why}" for n, why in failed.items()]
        more = f"; and {len(reasons) - 3} more" if len(reasons) > 3 else ""
        raise OrderError(f"{meth.name} identified none of the orders {_span(orders)} at past "
                         f"{past}, future {future} ({'; '.join(reasons[:3])}{more})")
    n_params = [n * (2 * ell + m) + (ell * m if feed else 0) + n * len(flights) for n in orders]
    ld_arr, d_arr = np.array(log_det, dtype=float), np.array(n_params, dtype=float)
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
        chosen={k: orders[_argmin(v)] for k, v in crit.items()}, failed=failed)


def _log_det(meth: Method, flights: Sequence[IOData], *, order: int, past: int, future: int,
             options: Any, products: Any) -> float:
    """``log det`` of the one-step error covariance of the order-``order`` model (``inf``
    when it is not positive definite or not finite)."""
    # a warning per order would flood the log; the covariance is computed here (below), once
    with quiet_models(), without_own_noise_cov():
        model = meth.identify(flights, order=order, past=past, future=future, options=options,
                              products=products)
    errs, _ = one_step_errors(model, flights=flights)  # a Kalman gain if A - K C is unstable
    with np.errstate(over="ignore", invalid="ignore"):
        cov = error_covariance(errs)
    sign, ld = np.linalg.slogdet(cov) if np.isfinite(cov).all() else (0.0, np.inf)
    return float(ld) if sign > 0 else np.inf


def _span(orders: Sequence[int]) -> str:
    """``1..12`` for consecutive orders, else ``2, 4, 8``."""
    if len(orders) > 2 and list(orders) == list(range(orders[0], orders[-1] + 1)):
        return f"{orders[0]}..{orders[-1]}"
    return ", ".join(map(str, orders))


def _argmin(values: np.ndarray) -> int:
    """Index of the smallest value among those that are not NaN (failed orders)."""
    scored = np.flatnonzero(~np.isnan(values))
    return int(scored[np.argmin(values[scored])])


#: Smallest singular-value gap, decades (a factor of 2), that :func:`suggest_order` takes
#: as a clear cut between signal and noise.
GAP_MIN_DECADES = 0.3
#: A gap smaller than this, decades (a factor of 10), gives way when AIC, AICc and BIC all pick
#: more states: a modest drop of the singular values is then a change of scale between groups
#: of modes, not the end of the signal (a demo flight: 0.5 decades after s_3, every criterion
#: 11, held-out validation 8; order 3 fitted acc.z 0 %).
GAP_STRONG_DECADES = 1.0
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
    gap of at least ``min_gap`` decades (a factor of 2), unless it is under
    :data:`GAP_STRONG_DECADES` and AIC, AICc and BIC all pick more states. A largest gap right
    after the first value is degenerate (one dominant direction, e.g. the thrust's scale, says
    nothing about
    the order of the rest) and a smaller gap is no cut between signal and noise; the
    suggestion is then BIC's order (AIC over-fits long records), as it is when the gap's
    order is one the method failed to identify (``ic.failed``). Validation on held-out data
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
    scored = ic.scored
    edge = (" (the largest order scored: the best may lie beyond)"
            if scored.size > 1 and bic == int(scored[-1]) else "")
    if capped:
        why = (f"the singular values after s_{max_order} are zero because these horizons "
               f"allow at most {max_order} (the rank cap), not because of the data: the order "
               "may be higher; use a longer past")
        return OrderSuggestion(order=bic, rule="bic", by_rule=by_rule, gaps=gaps,
                               gap_decades=decades, gap_clear=False,
                               reason=f"BIC{edge}; gap rule not used: {why}")
    if clear and gap_order in ic.failed:
        why = (f"the singular values drop by {decades:.2f} decades after s_{gap_order}, but "
               f"order {gap_order} could not be identified ({ic.failed[gap_order]})")
        return OrderSuggestion(order=bic, rule="bic", by_rule=by_rule, gaps=gaps,
                               gap_decades=decades, gap_clear=True,
                               reason=f"BIC{edge}; gap rule not used: {why}")
    fewer = min(by_rule[k] for k in ("aic", "aicc", "bic"))
    if clear and decades < GAP_STRONG_DECADES and fewer > gap_order:
        why = (f"the singular values drop by {decades:.2f} decades after s_{gap_order} (under "
               f"{GAP_STRONG_DECADES:g}), but AIC, AICc and BIC all pick more states "
               f"({by_rule['aic']}, {by_rule['aicc']}, {by_rule['bic']})")
        return OrderSuggestion(order=bic, rule="bic", by_rule=by_rule, gaps=gaps,
                               gap_decades=decades, gap_clear=True,
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
