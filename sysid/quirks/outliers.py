"""**Outliers** (:func:`find_outliers`). A gross outlier (a corrupted log sample, a sensor glitch)
is one sample of one channel far from what the samples around it say it should be. Each
channel of the joint signal :math:`w(k) = [u(k); y(k)]` is predicted one step ahead from the
:math:`L` samples *before* it and, separately, from the :math:`L` samples *after* it (two
least-squares VAR models of order :math:`L` on all channels, pooled over the records; :math:`L`
the data's memory, :func:`sysid.memory.predictor_memory`, at most :data:`MAX_LAG`). Each
prediction error is divided by its robust scale, :math:`1.4826` times its median absolute
deviation over all the samples (the scale of the *residual*, not of the signal: a lightly
damped, slow or drifting signal is predicted well and is not flagged), and a sample is flagged
when *both* exceed the threshold :math:`T`:

.. math:: \\min\\big(|e^{f}_{k}| / \\hat\\sigma^{f},\\ |e^{b}_{k}| / \\hat\\sigma^{b}\\big) > T.

A sample that departs from the ones before and after it is an additive outlier: both predictions
miss it by about the same amount, on the same side, because both predict the value it should
have had. A step (a staircase input, a level change) is unexpected from one side and its two
predictions disagree (the old level and the new one): a sample is flagged only when the two
predictions are closer to each other than either is to it (:data:`AGREEMENT`), so a step is not
flagged even where the backward predictor, fitted across the levels of a staircase, misses it
too (DaISy cstr's input, held 10 samples a level: 23 and 11 robust standard deviations at its
largest step, the predictions 1.3 times as far apart as the nearer is from the sample;
CrazyPAD's logged cmd_roll spike, flagged: 0.8 times). The samples after an outlier (which carry
it in their regressors) are predicted well from the other side, so they are not flagged either.
Channels whose values sit on a grid (PWM counts, a quantised sensor, a binary input) take the
grid's step as the least scale: a one-step flicker is not an outlier. The model is fitted twice,
the second time without the rows that hold a flagged sample.

The threshold comes from the Gaussian tail and the number :math:`n` of samples tested (all
channels): :math:`T = \\Phi^{-1}(1 - \\alpha / 2n)` with :math:`\\alpha` =
:data:`FALSE_ALARM` (Bonferroni), at least :data:`MIN_THRESHOLD`; on clean Gaussian data a
false alarm then comes in about one call of a hundred, whatever the record length
(:math:`T` = 5.7 for :math:`10^6` samples). The first and last :math:`L` samples of a record
are not tested. Replace what is found by interpolation with :func:`sysid.preprocess.despike`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from statistics import NormalDist

import numpy as np

from sysid.data import IOData, as_flights
from sysid.memory import predictor_memory

__all__ = ["AGREEMENT", "FALSE_ALARM", "MAX_LAG", "MIN_THRESHOLD", "SHOWN", "Outliers",
           "find_outliers", "outlier_masks", "outlier_threshold", "outlier_warnings"]

#: Chance of one false alarm or more on clean Gaussian data, per call (Bonferroni).
FALSE_ALARM = 0.01
#: Least threshold, robust standard deviations (short records).
MIN_THRESHOLD = 10.0
#: Longest lag of the two one-step predictors, samples.
MAX_LAG = 10
#: An outlier's two predictions (from before and from after it) agree with each other: they
#: differ by at most this share of the smaller distance from the sample (module docstring):
#: 1, the two predictions are closer to each other than either is to the sample.
AGREEMENT = 1.0
#: Places listed in a warning (the count says how many more).
SHOWN = 4
#: The 97.5th percentile of the standard normal distribution.
_Z95 = NormalDist().inv_cdf(0.975)
#: Rows of the regression per chunk (bounds the memory on long records).
_CHUNK = 50_000


@dataclass(frozen=True)
class Outliers:
    """The flagged samples of one channel: ``name``, ``kind`` (``"input"``/``"output"``),
    ``column`` (index in ``u`` or ``y``), ``where`` the ``(record, sample)`` pairs, ``size``
    how far each is, in robust standard deviations (the smaller of its two prediction
    errors), and the ``threshold`` used."""

    name: str
    kind: str
    column: int
    where: tuple[tuple[int, int], ...]
    size: tuple[float, ...]
    threshold: float


def outlier_threshold(n_tested: int, *, alpha: float = FALSE_ALARM) -> float:
    """:math:`\\max(\\Phi^{-1}(1 - \\alpha / 2n),` :data:`MIN_THRESHOLD`:math:`)` for ``n_tested``
    samples (all channels), robust standard deviations."""
    if n_tested < 1:
        return MIN_THRESHOLD
    return max(MIN_THRESHOLD, -NormalDist().inv_cdf(alpha / (2.0 * n_tested)))


def _lag(flights: Sequence[IOData], lag: int | None) -> int:
    if lag is None:
        lag = predictor_memory(flights, max_lag=MAX_LAG).lag
    return int(min(max(lag, 1), MAX_LAG))


def _windows(w: np.ndarray, lag: int, start: int, stop: int) -> np.ndarray:
    """Windows ``w[i : i + lag + 1]`` for ``i`` in ``start..stop-1``: (rows, lag + 1, c)."""
    return np.lib.stride_tricks.sliding_window_view(w[start:stop + lag], lag + 1, axis=0
                                                    ).transpose(0, 2, 1)


def _design(win: np.ndarray, side: str) -> tuple[np.ndarray, np.ndarray]:
    """Regressors (with an intercept) and targets of the forward (``"f"``: the last sample
    of each window from the others) or backward (``"b"``: the first) predictor."""
    rows = win.shape[0]
    if side == "f":
        x, y = win[:, :-1][:, ::-1], win[:, -1]
    else:
        x, y = win[:, 1:], win[:, 0]
    return np.hstack([x.reshape(rows, -1), np.ones((rows, 1))]), y


def _fit(ws: Sequence[np.ndarray], lag: int, side: str, bad: Sequence[np.ndarray]
         ) -> np.ndarray:
    """Least-squares coefficients, rows with a sample of ``bad`` left out."""
    c = ws[0].shape[1]
    gram = np.zeros((c * lag + 1, c * lag + 1))
    cross = np.zeros((c * lag + 1, c))
    for w, b in zip(ws, bad, strict=True):
        n_rows = w.shape[0] - lag
        hit = np.convolve(b.any(axis=1).astype(float), np.ones(lag + 1), "valid") > 0
        for a in range(0, n_rows, _CHUNK):
            z = min(a + _CHUNK, n_rows)
            x, y = _design(_windows(w, lag, a, z), side)
            keep = ~hit[a:z]
            x, y = x[keep], y[keep]
            gram += x.T @ x
            cross += x.T @ y
    ridge = 1e-10 * max(np.trace(gram), 1.0) / gram.shape[0]
    return np.linalg.solve(gram + ridge * np.eye(gram.shape[0]), cross)


def _errors(w: np.ndarray, lag: int, side: str, coef: np.ndarray) -> np.ndarray:
    """Prediction errors (N, c), NaN where the predictor has no samples."""
    out = np.full(w.shape, np.nan)
    n_rows = w.shape[0] - lag
    for a in range(0, n_rows, _CHUNK):
        z = min(a + _CHUNK, n_rows)
        x, y = _design(_windows(w, lag, a, z), side)
        off = a + lag if side == "f" else a
        out[off:off + z - a] = y - x @ coef
    return out


def _grid_step(x: np.ndarray) -> float:
    """The smallest non-zero change between consecutive samples: the step of a channel whose
    values sit on a grid, about zero otherwise."""
    d = np.abs(np.diff(x))
    span = float(np.ptp(x)) if x.size else 0.0
    d = d[d > 1e-9 * span]
    return float(d.min()) if d.size else 0.0


def _robust_scale(e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Median and robust standard deviation per column, NaNs left out: the larger of 1.4826
    times the median absolute deviation and the 95th percentile of the absolute deviations
    over 1.96, both the standard deviation for Gaussian errors (module docstring)."""
    med = np.nanmedian(e, axis=0)
    dev = np.abs(e - med)
    return med, np.maximum(1.4826 * np.nanmedian(dev, axis=0),
                           np.nanpercentile(dev, 95.0, axis=0) / _Z95)


def _flag(flights: Sequence[IOData], lag: int, bad: list[np.ndarray], *, alpha: float
          ) -> tuple[list[np.ndarray], float]:
    """One pass: fit both predictors without the rows of ``bad``; each sample's distance
    (N, c) in robust standard deviations (NaN where untested) and the threshold."""
    ws, scale = _standardised(flights)
    dist = [np.full(w.shape, np.inf) for w in ws]
    centred: dict[str, list[np.ndarray]] = {}
    for side in ("f", "b"):
        coef = _fit(ws, lag, side, bad)
        errs = [_errors(w, lag, side, coef) for w in ws]
        med, sd = _robust_scale(np.vstack(errs))
        centred[side] = [e - med for e in errs]
        step = np.array([max(_grid_step(w[:, j]) for w in ws) for j in range(ws[0].shape[1])])
        sd = np.maximum(sd, step)
        with np.errstate(invalid="ignore", divide="ignore"):
            for d, e in zip(dist, centred[side], strict=True):
                z = np.abs(e) / sd
                z[:, (sd <= 0) | (scale <= 0)] = 0.0
                np.minimum(d, z, out=d)
    for d, ef, eb in zip(dist, centred["f"], centred["b"], strict=True):
        with np.errstate(invalid="ignore"):  # the two sides disagree: a step, not an outlier
            d[np.abs(ef - eb) > AGREEMENT * np.minimum(np.abs(ef), np.abs(eb))] = 0.0
        d[~np.isfinite(d)] = np.nan
    n_tested = sum(int(np.isfinite(d).sum()) for d in dist)
    return dist, outlier_threshold(n_tested, alpha=alpha)


def _standardised(flights: Sequence[IOData]) -> tuple[list[np.ndarray], np.ndarray]:
    """Each record's joint signal less its mean, divided by one pooled standard deviation a
    channel (a constant channel left as zeros)."""
    ws = [d.w - d.w.mean(axis=0) for d in flights]
    scale = np.sqrt(sum((w ** 2).sum(axis=0) for w in ws) / sum(len(w) for w in ws))
    return [w / np.where(scale > 0, scale, 1.0) for w in ws], scale


def _distances(flights: Sequence[IOData], *, lag: int | None, alpha: float
               ) -> tuple[list[np.ndarray], float]:
    """Each sample's distance (N, c) in robust standard deviations (NaN where untested: the
    first and last ``lag`` samples, records too short, data too few for the predictors) and
    the threshold, after the second fit."""
    flights = list(as_flights(flights))
    lag = _lag(flights, lag)
    out = [np.full(d.w.shape, np.nan) for d in flights]
    usable = [i for i, d in enumerate(flights) if d.n_samples >= 2 * lag + 2]
    sub = [flights[i] for i in usable]
    if not sub or sum(d.n_samples - lag for d in sub) < 5 * (lag * sub[0].w.shape[1] + 1):
        return out, MIN_THRESHOLD
    dist, thr = _flag(sub, lag, [np.zeros(d.w.shape, dtype=bool) for d in sub], alpha=alpha)
    dist, thr = _flag(sub, lag, [np.nan_to_num(d, nan=0.0) > thr for d in dist], alpha=alpha)
    for i, d in zip(usable, dist, strict=True):
        out[i] = _isolated(d, thr, lag)
    return out, thr


def _isolated(dist: np.ndarray, thr: float, lag: int) -> np.ndarray:
    """``dist`` (N, c) with the samples beyond ``thr`` that are not isolated set to 0: those
    with another sample beyond it, of any channel, at another instant less than ``lag + 1``
    samples away (an event the dynamics spread over several samples, such as a step, not one
    corrupted sample; several channels at the same instant are one corrupted sample)."""
    hit = np.nan_to_num(dist, nan=0.0) > thr
    times = np.flatnonzero(hit.any(axis=1))
    if times.size < 2:
        return dist
    gap = np.diff(times) <= lag
    near = np.zeros(times.size, dtype=bool)
    near[1:] |= gap
    near[:-1] |= gap
    out = dist.copy()
    out[times[near]] = np.where(hit[times[near]], 0.0, out[times[near]])
    return out


def outlier_masks(flights: Sequence[IOData], *, lag: int | None = None,
                  alpha: float = FALSE_ALARM) -> list[np.ndarray]:
    """Which samples are outliers (module docstring), one boolean array (N, m + l) a record,
    columns as ``IOData.w`` (inputs, then outputs).

    Parameters
    ----------
    flights : records of one system (same channels).
    lag : samples of each predictor; default the data's memory, at most :data:`MAX_LAG`.
    alpha : chance of a false alarm on clean Gaussian data.

    Returns
    -------
    list of (N_i, m + l) bool arrays.
    """
    dist, thr = _distances(flights, lag=lag, alpha=alpha)
    return [np.nan_to_num(d, nan=0.0) > thr for d in dist]


def find_outliers(flights: Sequence[IOData], *, lag: int | None = None,
                  alpha: float = FALSE_ALARM) -> list[Outliers]:
    """The channels with outliers (module docstring), inputs first; empty when none.

    Parameters
    ----------
    flights : records of one system (same channels), each ``u`` (N, m), ``y`` (N, l).
    lag : samples of each predictor; default the data's memory, at most :data:`MAX_LAG`.
    alpha : chance of a false alarm on clean Gaussian data (sets the threshold).

    Returns
    -------
    list of :class:`Outliers`, one per channel with at least one flagged sample.
    """
    flights = list(flights)
    dist, thr = _distances(flights, lag=lag, alpha=alpha)
    ref = flights[0]
    names = [*ref.input_names, *ref.output_names]
    out = []
    for j, name in enumerate(names):
        where, size = [], []
        for e, d in enumerate(dist):
            for k in np.flatnonzero(np.nan_to_num(d[:, j], nan=0.0) > thr):
                where.append((e, int(k)))
                size.append(float(d[k, j]))
        if where:
            kind, col = ("input", j) if j < ref.n_inputs else ("output", j - ref.n_inputs)
            out.append(Outliers(name=name, kind=kind, column=col, where=tuple(where),
                                size=tuple(size), threshold=thr))
    return out


def _place(flights: Sequence[IOData], record: int, sample: int) -> str:
    """``"5.556 s from the start of log00.h5#airborne-1"`` (the record's source, else its
    number): the time from the record's first sample, not the session's clock."""
    t = f"{sample * flights[record].dt:.6g} s"
    if flights[record].source:
        return f"{t} from the start of {flights[record].source}"
    return t if len(flights) == 1 else f"{t} of record {record + 1}"


def outlier_warnings(flights: Sequence[IOData], *, lag: int | None = None,
                     alpha: float = FALSE_ALARM) -> list[str]:
    """One line per channel with outliers (:func:`find_outliers`): the count, the largest
    few places and the remedy.

    Parameters
    ----------
    flights : records of one system, ``u`` (N, m), ``y`` (N, l).
    lag, alpha : as :func:`find_outliers`.

    Returns
    -------
    list of str, empty when no channel has outliers.
    """
    flights = list(flights)
    out = []
    for o in find_outliers(flights, lag=lag, alpha=alpha):
        order = np.argsort(o.size)[::-1][:SHOWN]
        places = ", ".join(_place(flights, *o.where[i]) for i in sorted(order))
        more = f" and {len(o.where) - SHOWN} more" if len(o.where) > SHOWN else ""
        out.append(f"{o.kind} {o.name}: {len(o.where)} sample(s) beyond {o.threshold:.1f} "
                   f"robust standard deviations of its one-step prediction errors from the "
                   f"samples before and after (outliers?), at {places}{more} (up to "
                   f"{max(o.size):.0f}); replace them by interpolation "
                   f"(sysid.preprocess.despike) or cut them out")
    return out
