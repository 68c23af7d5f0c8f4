"""Residual analysis of an identified model, as MATLAB's ``resid`` draws it.

A model is good for its data when its one-step prediction errors (the innovations
:math:`\\varepsilon(t) = y(t) - \\hat y(t|t-1)`, from :func:`sysid.validate.predict` with
``horizon=1``) are

* **white**: no autocorrelation left at lags :math:`k \\ne 0` (otherwise the noise model, i.e.
  the order or K, misses dynamics), and
* **independent of past inputs**: no cross-correlation with :math:`u(t-k)`, :math:`k \\ge 0`
  (otherwise B, D or the order miss input dynamics).

Per output channel ``c`` and input ``i``, with every flight's residuals and inputs made zero-mean
and the lag products summed over flights (never across a join) before dividing by the total
sample count :math:`N`:

.. math::

    \\rho_{\\varepsilon}(k) = \\frac{\\sum_t \\varepsilon_c(t)\\,\\varepsilon_c(t-k)}
        {\\sum_t \\varepsilon_c(t)^2},\\qquad
    \\rho_{\\varepsilon u}(k) = \\frac{\\sum_t \\varepsilon_c(t)\\,u_i(t-k)}
        {\\sqrt{\\sum_t \\varepsilon_c(t)^2 \\sum_t u_i(t)^2}} .

**Lag convention** (MATLAB's): a positive lag ``k`` pairs the residual with the input ``k``
samples *earlier*, so positive lags test past inputs; negative lags pair it with later inputs,
which in closed loop are correlated with it through the controller and are shown, not judged.

**Bounds.** For a white residual :math:`\\rho_{\\varepsilon}(k)`, :math:`k \\ne 0`, is about
normal with variance :math:`1/N`; the band is :math:`\\pm z/\\sqrt N` with :math:`z` the two-sided
normal quantile of ``confidence`` (2.58 at 0.99), as MATLAB draws it. For the cross-correlation of
a residual independent of the input, Bartlett's formula gives variance
:math:`(1/N) \\sum_{|j| \\le M} \\rho_{\\varepsilon}(j) \\rho_{u}(j)` (which is :math:`1/N` for a
white residual and grows when both are coloured); the band uses it. This is the factor of
MATLAB's ``resid`` (Ljung, *System Identification*, 2nd ed., section 16.6: the sum of the
products of the two autocorrelations), summed here over :math:`|j| \\le M`.

**Verdicts.** Whiteness: the Ljung-Box statistic
:math:`Q = N (N+2) \\sum_{k=1}^{M} \\rho_{\\varepsilon}(k)^2 / (N-k)`, :math:`\\chi^2_M` under
whiteness; white when its p-value is at least ``1 - confidence``. Independence: per input,
Ljung's test of the judged lags :math:`k_0..M` of the cross-correlation,
:math:`r = (\\rho_{\\varepsilon u}(k_0), ..., \\rho_{\\varepsilon u}(M))`:
:math:`Q_u = N r^T P^{-1} r` with
:math:`P_{kj} = \\sum_{|i| \\le M} \\rho_{\\varepsilon}(i) \\rho_u(i + j - k)` the covariance of
those lags times :math:`N` (:math:`P_{kk}` is the band's factor), :math:`\\chi^2` with as many
degrees of freedom as judged lags (fewer if :math:`P` is singular). A coloured input correlates
neighbouring lags: summing their squares as if independent raised the false alarms at 99 % to
about 20 % for an input with a pole at 0.95. :math:`k_0 = 0` for a model with feedthrough
(D != 0), :math:`k_0 = 1` without (its predictor does not use :math:`u(t)`, and a controller
without delay makes :math:`u(t)` depend on :math:`\\varepsilon(t)`); independent when every
input's p-value is at least ``(1 - confidence) / m`` (Bonferroni over the inputs). The fraction
of lags outside the band is reported beside each.
"""

from __future__ import annotations

import logging
import textwrap
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData, as_flights
from sysid.errors import DataError, DimensionError, ParameterError
from sysid.kalman import one_step_errors
from sysid.model import StateSpaceModel

__all__ = ["ResidualResult", "residuals"]

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class ResidualResult:
    """Result of :func:`residuals`. ``M`` is ``max_lag``, ``l`` outputs, ``m`` inputs.

    Attributes:
        residuals: one-step prediction errors per flight, each ``(N_i, l)``.
        lags: ``(M+1,)`` lags 0..M of ``autocorr``.
        autocorr: ``(M+1, l)`` normalised autocorrelation (1 at lag 0).
        auto_bound: ``z / sqrt(N)``, the band of ``autocorr`` at lags >= 1.
        cross_lags: ``(2M+1,)`` lags -M..M of ``crosscorr`` (positive: past inputs).
        crosscorr: ``(2M+1, l, m)`` normalised cross-correlation with each input.
        cross_bound: ``(l, m)`` band of ``crosscorr`` (Bartlett, see the module docstring).
        auto_outside: ``(l,)`` fraction of lags 1..M outside ``auto_bound``.
        cross_outside: ``(l, m)`` fraction of the judged lags ``first_lag..M`` outside
            ``cross_bound``.
        q_stat, p_value: ``(l,)`` Ljung-Box statistic and its p-value.
        cross_q, cross_p: ``(l, m)`` Ljung's statistic over the judged lags (with their
            covariance; module docstring) and its p-value.
        first_lag: first judged cross-correlation lag (0 with feedthrough, else 1).
        white, independent: ``(l,)`` verdicts at ``confidence``.
        n_samples: total samples ``N`` over flights; ``confidence``, ``max_lag`` as given.
        stabilised: True if the predictor A - KC was unstable and the steady-state Kalman gain
            (:func:`sysid.stable_predictor`) was used instead of the model's K.
    """

    residuals: tuple[np.ndarray, ...]
    lags: np.ndarray
    autocorr: np.ndarray
    auto_bound: float
    cross_lags: np.ndarray
    crosscorr: np.ndarray
    cross_bound: np.ndarray
    auto_outside: np.ndarray
    cross_outside: np.ndarray
    q_stat: np.ndarray
    p_value: np.ndarray
    cross_q: np.ndarray
    cross_p: np.ndarray
    white: np.ndarray
    independent: np.ndarray
    n_samples: int
    confidence: float
    max_lag: int
    first_lag: int
    output_names: tuple[str, ...]
    input_names: tuple[str, ...]
    stabilised: bool

    def summary(self) -> str:
        """Plain-text table: one line per output channel, columns aligned."""
        lines = [f"residual analysis: {self.n_samples} samples; whiteness over lags "
                 f"1..{self.max_lag}, independence of the inputs over lags "
                 f"{self.first_lag}..{self.max_lag}; {100 * self.confidence:g}% bounds "
                 f"(auto ±{self.auto_bound:.3f})"]
        if self.stabilised:
            lines.append("(predictor A - KC unstable: steady-state Kalman gain used)")
        rows = [("output", "white", "outside", "Q", "p", "indep.", "outside",
                 "worst input (p)")]
        for c, name in enumerate(self.output_names):
            worst = int(np.argmin(self.cross_p[c]))
            rows.append((name, "yes" if self.white[c] else "NO",
                         f"{100 * self.auto_outside[c]:.1f}%", f"{self.q_stat[c]:.4g}",
                         f"{self.p_value[c]:.3g}", "yes" if self.independent[c] else "NO",
                         f"{100 * self.cross_outside[c].max():.1f}%",
                         f"{self.input_names[worst]} ({self.cross_p[c, worst]:.3g})"))
        widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
        right = {2, 3, 6}  # numbers right-aligned
        lines += ["  ".join(cell.rjust(w) if i in right else cell.ljust(w)
                            for i, (cell, w) in enumerate(zip(r, widths, strict=True))).rstrip()
                  for r in rows]
        return "\n".join(lines)

    def legend(self) -> str:
        """What the columns of :meth:`summary` mean and how to read p, a few lines under the
        table: the text output of ``sysid resid`` and ``sysid compare --residuals`` (their
        ``--json`` has no table, so no legend)."""
        alpha = 1 - self.confidence
        m = len(self.input_names)
        each = f"{alpha / m:.2g} ({alpha:.2g}/{m})" if m > 1 else f"{alpha:.2g}"
        lags = f"lags {self.first_lag}..{self.max_lag}"
        rows = [("white", f"Ljung-Box test of the autocorrelation at lags 1..{self.max_lag}: "
                          f"yes when p >= {alpha:.2g}"),
                ("outside", f"share of those lags beyond ±{self.auto_bound:.3f} (about "
                            f"{100 * alpha:g}% for a white residual)"),
                ("Q, p", "the test's statistic and p-value"),
                ("indep.", f"no correlation with past inputs ({lags}): yes when every "
                           f"input's p >= {each}"),
                ("outside", "largest share of those lags beyond an input's bounds"),
                ("worst input (p)", "the input of the smallest p")]
        width = max(len(key) for key, _ in rows)
        advice = (f"reading p: over {self.n_samples} samples a tiny departure from whiteness "
                  "gives p ~ 0 and NO (the bounds narrow as 1/sqrt(N) too); read the "
                  "autocorrelation outside the bounds as well: a few lags just beyond them is a "
                  "residual near white, many lags or far beyond them are dynamics the model "
                  "misses (each lag: sysid resid --json or --rrd).")
        return "\n".join([*(f"  {key.ljust(width)}  {text}" for key, text in rows),
                          *textwrap.wrap(advice, width=96, initial_indent="  ",
                                         subsequent_indent="  ")])

    def to_json(self) -> dict[str, object]:
        """The verdicts and correlations as plain lists (for ``--json``)."""
        return {
            "n_samples": self.n_samples, "confidence": self.confidence, "max_lag": self.max_lag,
            "first_lag": self.first_lag, "auto_bound": self.auto_bound,
            "stabilised": self.stabilised,
            "outputs": [{
                "name": name, "white": bool(self.white[c]),
                "auto_outside": float(self.auto_outside[c]), "q_stat": float(self.q_stat[c]),
                "p_value": float(self.p_value[c]), "independent": bool(self.independent[c]),
                "autocorr": self.autocorr[:, c].tolist(),
                "inputs": [{
                    "name": iname, "cross_bound": float(self.cross_bound[c, i]),
                    "cross_outside": float(self.cross_outside[c, i]),
                    "q_stat": float(self.cross_q[c, i]), "p_value": float(self.cross_p[c, i]),
                    "crosscorr": self.crosscorr[:, c, i].tolist()}
                    for i, iname in enumerate(self.input_names)]}
                for c, name in enumerate(self.output_names)]}


def _lag_sums(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """``S[k, i, j] = sum_t a_i(t) b_j(t-k)`` for k in -M..M, shape (2M+1, ca, cb)."""
    n = a.shape[0]
    out = np.zeros((2 * max_lag + 1, a.shape[1], b.shape[1]))
    for k in range(-max_lag, max_lag + 1):
        if abs(k) >= n:
            continue
        aa, bb = (a[k:], b[: n - k]) if k >= 0 else (a[: n + k], b[-k:])
        out[k + max_lag] = aa.T @ bb
    return out


def _independence_test(past: np.ndarray, rho_e: np.ndarray, rho_u: np.ndarray, *,
                       n_total: int) -> tuple[np.ndarray, np.ndarray]:
    """Portmanteau statistic and p-value ``(l, m)`` of the judged cross-correlations ``past``
    ``(J, l, m)`` (module docstring): ``Q = N r^T P^-1 r``, ``P`` the Toeplitz matrix of
    ``c(d) = sum_{|j|<=M} rho_e(j) rho_u(j+d)``; ``rho_e`` ``(2M+1, l)`` at lags -M..M,
    ``rho_u`` ``(4M+1, m)`` at lags -2M..2M. Directions of ``P`` without weight (eigenvalues
    under 1e-10 of the largest, or negative from the truncated sums) are left out, and
    the degrees of freedom with them."""
    from scipy import stats

    n_lags, ell, m = past.shape
    big = (rho_u.shape[0] - 1) // 2  # 2M
    half = (rho_e.shape[0] - 1) // 2  # M
    window = np.stack([rho_u[big - half + d: big + half + d + 1] for d in range(n_lags)])
    c = np.einsum("jc,djm->dcm", rho_e, window)  # (J, l, m), c(d) for d = 0..J-1
    gap = np.abs(np.subtract.outer(np.arange(n_lags), np.arange(n_lags)))
    q, p = np.zeros((ell, m)), np.ones((ell, m))
    for o in range(ell):
        for i in range(m):
            w, v = np.linalg.eigh(c[gap, o, i])
            keep = w > 1e-10 * max(w.max(initial=0.0), 0.0)
            if not keep.any():
                continue
            q[o, i] = n_total * np.sum((v[:, keep].T @ past[:, o, i]) ** 2 / w[keep])
            p[o, i] = stats.chi2.sf(q[o, i], df=int(keep.sum()))
    return q, p


def residuals(model: StateSpaceModel, data: IOData | Sequence[IOData], *, max_lag: int = 25,
              confidence: float = 0.99) -> ResidualResult:
    """Whiteness and input independence of ``model``'s one-step residuals on ``data``.

    ``data`` is one IOData or a list of flights (correlations summed per flight, never across
    a join). See the module docstring for the formulas, bounds, lag convention and verdicts.
    A model whose predictor ``A - KC`` is unstable is analysed with the steady-state Kalman
    gain (logged, ``stabilised=True``): its own predictor would diverge.
    """
    from scipy import stats

    if isinstance(max_lag, bool) or not isinstance(max_lag, int | np.integer) or max_lag < 1:
        raise ParameterError(f"max_lag={max_lag!r}; pass a positive whole number of samples")
    if not 0.5 < confidence < 1:
        raise ParameterError(f"confidence={confidence!r}; pass a probability in (0.5, 1)")
    flights = as_flights(data)
    m, ell = model.n_inputs, model.n_outputs
    if (flights[0].n_inputs, flights[0].n_outputs) != (m, ell):
        raise DimensionError(f"model has {m} inputs/{ell} outputs but data has "
                             f"{flights[0].n_inputs}/{flights[0].n_outputs}; select the matching "
                             "channels")
    if abs(flights[0].dt - model.dt) > 1e-6 * model.dt:
        raise DataError(f"data sampled at dt={flights[0].dt} s but the model has dt={model.dt} s;"
                        " resample the data to the model's rate (sysid.zoh_resample)")
    n_total = sum(d.n_samples for d in flights)
    if max_lag >= min(d.n_samples for d in flights):
        raise ParameterError(f"max_lag={max_lag} is not shorter than the shortest flight "
                             f"({min(d.n_samples for d in flights)} samples); pass a smaller one")
    if not model.predictor_is_stable:
        log.warning("predictor A - KC is unstable: residuals use the steady-state Kalman gain")
    errs, stabilised = one_step_errors(model, flights=flights)
    if not all(np.isfinite(e).all() for e in errs):
        raise DataError("one-step residuals diverged; check the model (its poles, its K)")
    ee = np.zeros((2 * max_lag + 1, ell, ell))
    eu = np.zeros((2 * max_lag + 1, ell, m))
    uu = np.zeros((4 * max_lag + 1, m))  # each input's own lags -2M..2M (the test's matrix)
    centred = [(e - e.mean(axis=0), d.u - d.u.mean(axis=0)) for d, e in zip(flights, errs,
                                                                           strict=True)]
    # each channel over its largest magnitude: correlations do not depend on the scale, and the
    # sums of products overflowed (1e80) or underflowed (1e-100) into wrong verdicts
    e_top = np.max([np.abs(e0).max(axis=0) for e0, _ in centred], axis=0)
    u_top = np.max([np.abs(u0).max(axis=0) for _, u0 in centred], axis=0)
    for e0, u0 in centred:
        e0, u0 = e0 / np.where(e_top > 0, e_top, 1.0), u0 / np.where(u_top > 0, u_top, 1.0)
        ee += _lag_sums(e0, e0, max_lag)
        eu += _lag_sums(e0, u0, max_lag)
        uu += np.diagonal(_lag_sums(u0, u0, 2 * max_lag), axis1=1, axis2=2)
    var_e = np.diag(ee[max_lag])
    var_u = uu[2 * max_lag]
    if np.any(var_e <= 0) or np.any(var_u <= 0):
        raise DataError("a residual or input channel is constant; correlations are undefined")
    rho_e = np.diagonal(ee, axis1=1, axis2=2) / var_e  # (2M+1, l), symmetric in k
    rho_u_wide = uu / var_u  # (4M+1, m), lags -2M..2M
    rho_u = rho_u_wide[max_lag: 3 * max_lag + 1]  # (2M+1, m)
    cross = eu / np.sqrt(var_e[None, :, None] * var_u[None, None, :])
    z = float(stats.norm.ppf(0.5 + confidence / 2))
    auto = rho_e[max_lag:]
    auto_bound = z / np.sqrt(n_total)
    bartlett = np.maximum(np.einsum("kc,ki->ci", rho_e, rho_u), 1e-12)  # (l, m)
    cross_bound = z * np.sqrt(bartlett / n_total)
    k = np.arange(1, max_lag + 1)
    q = n_total * (n_total + 2) * np.sum(auto[1:] ** 2 / (n_total - k)[:, None], axis=0)
    p = stats.chi2.sf(q, df=max_lag)
    first = 0 if np.any(model.D != 0) else 1
    past = cross[max_lag + first:]  # the judged lags first..M
    cross_q, cross_p = _independence_test(past, rho_e, rho_u_wide, n_total=n_total)
    alpha = 1 - confidence
    return ResidualResult(
        residuals=tuple(errs), lags=np.arange(max_lag + 1), autocorr=auto,
        auto_bound=float(auto_bound), cross_lags=np.arange(-max_lag, max_lag + 1),
        crosscorr=cross, cross_bound=cross_bound,
        auto_outside=np.mean(np.abs(auto[1:]) > auto_bound, axis=0),
        cross_outside=np.mean(np.abs(past) > cross_bound[None], axis=0),
        q_stat=q, p_value=p, cross_q=cross_q, cross_p=cross_p, white=p >= alpha,
        independent=np.all(cross_p >= alpha / m, axis=1), n_samples=n_total,
        confidence=float(confidence), max_lag=int(max_lag), first_lag=first,
        output_names=tuple(model.output_names), input_names=tuple(model.input_names),
        stabilised=stabilised,
    )
