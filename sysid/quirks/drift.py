"""**Drift** (:func:`trend_ratios`): the change of the least-squares line of a channel over a
record, :math:`|b|\\,(N - 1)\\,\\Delta t`, against the standard deviation of the channel about
that line. Above :data:`DRIFT_RATIO` the trend is as large as the signal's own excursions: a
subspace model explains it with a pole near 1 (an evaporator-like record with a drift of three
standard deviations over the record on one output: largest pole 0.9994 for a true 0.95).
Remove it with ``detrend="linear"`` (:func:`sysid.preprocess.detrend_data`, CLI ``--detrend
linear``) when it is no part of the dynamics.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sysid.data import IOData, as_flights

__all__ = ["AR_ORDER", "DRIFT_RATIO", "DRIFT_T", "drift_warnings", "trend_ratios"]

#: Warn when a linear trend changes by more than this many detrended standard deviations
#: over the record ...
DRIFT_RATIO = 1.0
#: ... and its t statistic against the channel's own slow variation exceeds this.
DRIFT_T = 5.0
#: Order of the AR model of a detrended channel that measures its slow variation.
AR_ORDER = 20


def _long_run_sd(r: np.ndarray) -> float:
    """Long-run standard deviation of a stationary series ``r`` (N,): that of its AR(p)
    innovations over :math:`|1 - \\sum a_i|` (p = :data:`AR_ORDER`, fewer on short
    records); inf when the AR coefficients sum to 1 or more (an integrating series: no
    trend is significant)."""
    n = r.size
    p = max(1, min(AR_ORDER, n // 10))
    x = np.column_stack([r[p - i - 1:n - i - 1] for i in range(p)])
    a, *_ = np.linalg.lstsq(x, r[p:], rcond=None)
    e = r[p:] - x @ a
    rest = 1.0 - float(a.sum())
    return float(np.sqrt(np.mean(e ** 2)) / rest) if rest > 1e-9 else float("inf")


def trend_ratios(flights: Sequence[IOData]) -> tuple[np.ndarray, np.ndarray]:
    """Each channel's linear trend over each record: its change in standard deviations of
    the detrended channel, and its t statistic against the channel's own slow variation
    (module docstring).

    Parameters
    ----------
    flights : records, each ``u`` (N, m), ``y`` (N, l).

    Returns
    -------
    ratio, t : (records, m + l) arrays, columns as ``IOData.w``; 0 for a constant channel
    or a record of fewer than 20 samples.
    """
    flights = list(as_flights(flights))
    shape = (len(flights), flights[0].w.shape[1])
    ratio, t = np.zeros(shape), np.zeros(shape)
    for i, d in enumerate(flights):
        n = d.n_samples
        if n < 20:
            continue
        tau = np.arange(n) - (n - 1) / 2.0
        w = d.w - d.w.mean(axis=0)
        slope = tau @ w / (tau @ tau)
        rest = w - tau[:, None] * slope[None, :]
        sd = np.sqrt(np.mean(rest ** 2, axis=0))
        for j in range(w.shape[1]):
            if sd[j] <= 1e-12 * (np.abs(w[:, j]).max() + 1e-300):
                continue
            ratio[i, j] = abs(slope[j]) * (n - 1) / sd[j]
            t[i, j] = abs(slope[j]) * np.sqrt(tau @ tau) / _long_run_sd(rest[:, j])
    return ratio, t


def drift_warnings(flights: Sequence[IOData], *, ratio: float = DRIFT_RATIO,
                   t_min: float = DRIFT_T) -> list[str]:
    """One line per output whose linear trend over a record changes by more than ``ratio``
    detrended standard deviations with a t statistic above ``t_min`` (:func:`trend_ratios`)
    where no input of that record drifts so (an output trend that comes with an input trend
    may be the response to it, which a model should explain), with the remedy. Inputs are
    not flagged themselves: a slowly moving input (a pilot's or an outer loop's command) is
    excitation, not a disturbance.

    Parameters
    ----------
    flights : records, each ``u`` (N, m), ``y`` (N, l).
    ratio : least change over the record, detrended standard deviations.
    t_min : least t statistic against the channel's own slow variation.

    Returns
    -------
    list of str, empty when no output drifts.
    """
    flights = list(flights)
    r, t = trend_ratios(flights)
    drifts = (r > ratio) & (t > t_min)
    m = flights[0].n_inputs
    quiet = ~drifts[:, :m].any(axis=1)
    out = []
    for j, name in enumerate(flights[0].output_names):
        hit = np.flatnonzero(drifts[:, m + j] & quiet)
        if not hit.size:
            continue
        worst = int(hit[np.argmax(r[hit, m + j])])
        where = "" if len(flights) == 1 else (
            f" in {hit.size} of {len(flights)} records (most in record {worst + 1})")
        out.append(f"output {name} drifts: its linear trend changes by {r[worst, m + j]:.1f} "
                   f"standard deviations of its detrended signal over the record{where} "
                   f"(t = {t[worst, m + j]:.0f} against its own slow variation; no input "
                   f"drifts so); a model takes that for a pole near 1: remove it (--detrend "
                   f"linear, sysid.preprocess.detrend_data(kind='linear')) unless it is "
                   f"dynamics")
    return out
