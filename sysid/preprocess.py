"""Preprocessing of flight logs for identification (thesis section 4.3.1).

The Crazyflie logs each block with its own firmware timestamp, so the channels of one flight are
sampled at slightly different, irregular instants. Subspace methods need every channel on one
uniform grid; the thesis "normalised the sampling times by applying a zero-order hold and
resampled the data against a common time vector at a uniform rate of 50 Hz". This module does
that, trims to a time window, removes a mean or linear trend (and gives it back so it can be
re-applied), and builds an :class:`~sysid.data.IOData` from named streams.

Zero-order hold: on the grid :math:`g_j = t_0 + j\\,\\Delta t`, a stream sampled at times
:math:`t_i` (non-decreasing) with values :math:`v_i` takes the value of the latest sample not
after the grid instant,

.. math::  \\tilde v(g_j) = v_{i^*},\\qquad i^* = \\max\\{\\, i : t_i \\le g_j + \\epsilon \\,\\},

where :math:`\\epsilon` (``atol``, default 1 ns) absorbs floating-point noise in timestamps that
are meant to lie on the grid. Time is in seconds throughout; convert firmware milliseconds once
when the log is read.

Trend removal: ``"mean"`` subtracts :math:`\\bar x` per channel; ``"linear"`` subtracts the
least-squares line :math:`a + b\\,(t - t_0)` per channel. The :class:`Trend` returned carries
:math:`a` (offset, channel units) and :math:`b` (slope, channel units per second) and can be
evaluated on any time vector to put the trend back (e.g. on a model's simulated output).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from sysid.data import IOData
from sysid.errors import DataError, DimensionError, ParameterError
from sysid.quirks import outlier_masks

__all__ = [
    "IOTrend",
    "Stream",
    "Trend",
    "despike",
    "detrend",
    "detrend_data",
    "iodata_from_streams",
    "resample_streams",
    "trim",
    "uniform_grid",
    "zoh_resample",
]

log = logging.getLogger(__name__)

TrendKind = Literal["mean", "linear"]


@dataclass(frozen=True)
class Stream:
    """One logged variable: samples ``values`` (n,) at their own times ``t`` (n,), seconds.

    ``t`` must be finite and non-decreasing (repeated instants are allowed: the last sample of a
    repeated instant wins under the zero-order hold). ``unit`` is the unit of ``values``.
    """

    name: str
    t: np.ndarray = field(repr=False)
    values: np.ndarray = field(repr=False)
    unit: str = ""

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        v = np.asarray(self.values, dtype=float)
        if t.ndim != 1 or v.ndim != 1 or t.shape != v.shape:
            raise DimensionError(
                f"stream {self.name!r}: t and values must be 1-D of equal length, "
                f"got {t.shape} and {v.shape}; pass one variable per Stream"
            )
        if t.size == 0:
            raise DataError(f"stream {self.name!r} is empty; drop it or log it")
        _check_finite(t, what=f"stream {self.name!r} time")
        _check_finite(v, what=f"stream {self.name!r}")
        back = np.flatnonzero(np.diff(t) < 0)
        if back.size:
            raise DataError(
                f"stream {self.name!r}: time goes backwards at sample {back[0] + 1} "
                f"({t[back[0]]:.6f} s -> {t[back[0] + 1]:.6f} s); sort it or unwrap the clock"
            )
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "values", v)


def _check_finite(x: np.ndarray, *, what: str) -> None:
    bad = ~np.isfinite(x)
    if bad.any():
        idx = np.argwhere(bad)[0]
        raise DataError(f"{what}: non-finite value at sample {idx[0]}; remove or repair it")


def zoh_resample(
    *, t: np.ndarray, values: np.ndarray, grid: np.ndarray, atol: float = 1e-9
) -> np.ndarray:
    """Zero-order-hold ``values`` sampled at ``t`` onto ``grid`` (module docstring equation).

    Parameters
    ----------
    t : (n,) non-decreasing sample times, seconds.
    values : (n,) or (n, c) samples.
    grid : (M,) target times, seconds, all ``>= t[0] - atol``.

    Returns
    -------
    (M,) or (M, c) array: for each grid instant the latest sample at or before it.
    """
    t = np.asarray(t, dtype=float)
    values = np.asarray(values)
    grid = np.asarray(grid, dtype=float)
    if values.shape[0] != t.shape[0]:
        raise DimensionError(
            f"values has {values.shape[0]} samples but t has {t.shape[0]}; pass matching arrays"
        )
    idx = np.searchsorted(t, grid + atol, side="right") - 1
    if idx.size and idx.min() < 0:
        first = int(np.argmax(idx < 0))
        raise DataError(
            f"grid instant {grid[first]:.6f} s precedes the first sample at {t[0]:.6f} s; "
            "start the grid at or after the first sample"
        )
    return values[idx]


def uniform_grid(
    *, streams: Sequence[Stream], dt: float, start: float | None = None, stop: float | None = None
) -> np.ndarray:
    """Uniform grid ``start + k dt`` (M,) covering the window where every stream has data.

    ``start`` defaults to the latest first sample of all streams (before it some channel has no
    value to hold) and ``stop`` (inclusive) to the earliest last sample (after it a channel
    would be held indefinitely). Both in seconds.
    """
    if not streams:
        raise DataError("no streams given; pass at least one Stream")
    if not dt > 0:
        raise DataError(f"dt = {dt} s; pass a positive sample period in seconds")
    first = max(s.t[0] for s in streams)
    last = min(s.t[-1] for s in streams)
    start = first if start is None else float(start)
    stop = last if stop is None else float(stop)
    if start < first - 1e-9:
        raise DataError(
            f"start {start:.6f} s precedes the first sample of some stream ({first:.6f} s); "
            f"use start >= {first:.6f}"
        )
    if stop < start:
        raise DataError(
            f"window [{start:.6f}, {stop:.6f}] s is empty; pick stop > start "
            f"(streams overlap on [{first:.6f}, {last:.6f}] s)"
        )
    n = int(np.floor((stop - start) / dt + 1e-9)) + 1
    return start + dt * np.arange(n)


def resample_streams(
    *,
    streams: Sequence[Stream],
    dt: float,
    start: float | None = None,
    stop: float | None = None,
    max_hold: float | None = None,
    source: str = "",
) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold every stream onto one uniform grid (thesis section 4.3.1).

    Returns ``(grid (M,), values (M, len(streams)))``, columns in the order of ``streams``.
    If ``max_hold`` (seconds) is given, a warning is logged for each stream that holds a value
    longer than that (a gap in the log: dropped packets), with the number of affected instants,
    after ``source`` (where the streams come from, e.g. a file) when given.
    """
    grid = uniform_grid(streams=streams, dt=dt, start=start, stop=stop)
    out = np.empty((grid.size, len(streams)))
    for j, s in enumerate(streams):
        idx = np.searchsorted(s.t, grid + 1e-9, side="right") - 1
        out[:, j] = s.values[idx]
        if max_hold is not None:
            age = grid - s.t[idx]
            n_stale = int(np.count_nonzero(age > max_hold))
            if n_stale:
                log.warning(
                    "%sstream %r: %d grid instants hold a sample older than %.3f s (log gaps)",
                    f"{source}: " if source else "", s.name, n_stale, max_hold,
                )
    return grid, out


def iodata_from_streams(
    *,
    streams: Sequence[Stream],
    inputs: Sequence[str],
    outputs: Sequence[str],
    dt: float,
    start: float | None = None,
    stop: float | None = None,
    max_hold: float | None = None,
    source: str = "",
) -> IOData:
    """Build an :class:`IOData` from named streams: ZOH onto one grid, inputs then outputs.

    ``inputs`` and ``outputs`` name streams (in the column order wanted); names and units are
    carried into the IOData. ``start``/``stop`` (seconds, stream time) trim the window.
    ``max_hold`` and ``source``: as :func:`resample_streams`; ``source`` is also the IOData's.
    """
    by_name = {s.name: s for s in streams}
    missing = [n for n in (*inputs, *outputs) if n not in by_name]
    if missing:
        raise DataError(f"no stream named {missing}; available: {sorted(by_name)}")
    if not inputs or not outputs:
        raise DataError("name at least one input and one output stream")
    chosen = [by_name[n] for n in (*inputs, *outputs)]
    _, values = resample_streams(
        streams=chosen, dt=dt, start=start, stop=stop, max_hold=max_hold, source=source
    )
    m = len(inputs)
    return IOData(
        u=values[:, :m],
        y=values[:, m:],
        dt=dt,
        input_names=list(inputs),
        output_names=list(outputs),
        input_units=[by_name[n].unit for n in inputs],
        output_units=[by_name[n].unit for n in outputs],
        source=source,
    )


def trim(data: IOData, *, start: float | None = None, stop: float | None = None) -> IOData:
    """Keep the samples of ``data`` with ``start <= data.time <= stop`` (seconds, inclusive).

    ``data.time`` is ``k dt`` from the first sample. Names and units are kept.
    """
    time = np.asarray(data.time, dtype=float)
    lo = time[0] if start is None else float(start)
    hi = time[-1] if stop is None else float(stop)
    keep = (time >= lo - 1e-9) & (time <= hi + 1e-9)
    if not keep.any():
        raise DataError(
            f"window [{lo:.6f}, {hi:.6f}] s holds no sample; data spans "
            f"[{time[0]:.6f}, {time[-1]:.6f}] s"
        )
    sl = slice(int(np.argmax(keep)), int(len(keep) - np.argmax(keep[::-1])))
    return _replace_arrays(data, u=data.u[sl], y=data.y[sl])


def _replace_arrays(data: IOData, *, u: np.ndarray, y: np.ndarray) -> IOData:
    """A copy of ``data`` with new ``u`` and ``y`` and the same dt, names, units and source."""
    return dataclasses.replace(data, u=u, y=y)


@dataclass(frozen=True)
class Trend:
    """A removed trend ``offset + slope (t - t0)`` per channel.

    ``offset`` (c,) in channel units, ``slope`` (c,) in channel units per second (zero for a
    mean trend), ``t0`` seconds.
    """

    offset: np.ndarray
    slope: np.ndarray
    t0: float = 0.0

    def evaluate(self, time: np.ndarray) -> np.ndarray:
        """The trend on ``time`` (N,) seconds: (N, c)."""
        time = np.asarray(time, dtype=float)
        return self.offset[None, :] + (time - self.t0)[:, None] * self.slope[None, :]

    def restore(self, x: np.ndarray, *, time: np.ndarray) -> np.ndarray:
        """Add the trend back to detrended samples ``x`` (N, c) taken at ``time`` (N,)."""
        x = np.asarray(x, dtype=float)
        if x.ndim != 2 or x.shape[1] != self.offset.size:
            raise DimensionError(
                f"x has shape {x.shape}; pass (N, {self.offset.size}) to match the trend"
            )
        return x + self.evaluate(time)


def detrend(
    x: np.ndarray, *, time: np.ndarray, kind: TrendKind = "mean"
) -> tuple[np.ndarray, Trend]:
    """Remove a per-channel mean or least-squares line from ``x`` (N, c) sampled at ``time`` (N,).

    Returns ``(x - trend, trend)``; ``trend.restore`` undoes it exactly.
    """
    x = np.asarray(x, dtype=float)
    time = np.asarray(time, dtype=float)
    if x.ndim != 2 or time.shape != (x.shape[0],):
        raise DimensionError(
            f"x {x.shape} and time {time.shape} must be (N, c) and (N,); pass matching arrays"
        )
    t0 = float(time[0])
    if kind == "mean":
        trend = Trend(offset=x.mean(axis=0), slope=np.zeros(x.shape[1]), t0=t0)
    elif kind == "linear":
        if x.shape[0] < 2:
            raise DataError("a linear trend needs at least 2 samples; use kind='mean'")
        tau = time - t0
        design = np.column_stack([np.ones_like(tau), tau])
        coef, *_ = np.linalg.lstsq(design, x, rcond=None)
        trend = Trend(offset=coef[0], slope=coef[1], t0=t0)
    else:
        raise DataError(f"detrend kind {kind!r} is unknown; use 'mean' or 'linear'")
    return x - trend.evaluate(time), trend


@dataclass(frozen=True)
class IOTrend:
    """Trends removed from the inputs (``u``) and outputs (``y``) of one IOData."""

    u: Trend
    y: Trend


def detrend_data(data: IOData, *, kind: TrendKind = "mean") -> tuple[IOData, IOTrend]:
    """Detrend inputs and outputs of ``data``; returns the new IOData and the removed trends."""
    time = np.asarray(data.time, dtype=float)
    u, tu = detrend(data.u, time=time, kind=kind)
    y, ty = detrend(data.y, time=time, kind=kind)
    return _replace_arrays(data, u=u, y=y), IOTrend(u=tu, y=ty)


def despike(data: IOData, *, mask: np.ndarray | None = None) -> tuple[IOData, int]:
    """Replace outliers by linear interpolation between the nearest good samples of their
    channel (the nearest good value at a record's ends).

    Parameters
    ----------
    data : one record, ``u`` (N, m), ``y`` (N, l).
    mask : (N, m + l) bool, the samples to replace, columns as ``data.w`` (inputs, then
        outputs); default those :func:`sysid.quirks.outlier_masks` finds in ``data`` alone.

    Returns
    -------
    The repaired copy (names, units, dt and source kept) and how many samples were replaced.
    """
    if not isinstance(data, IOData):
        raise ParameterError(f"data: pass one IOData record, not {type(data).__name__}")
    if mask is None:
        mask = outlier_masks([data])[0]
    w = np.array(data.w, dtype=float)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != w.shape:
        raise DimensionError(f"mask has shape {mask.shape}; pass {w.shape} (samples, inputs "
                             "then outputs) to match the data")
    k = np.arange(w.shape[0])
    for j in np.flatnonzero(mask.any(axis=0)):
        good = ~mask[:, j]
        if not good.any():
            raise DataError(f"every sample of channel {j} is marked; nothing to interpolate "
                            "from")
        w[~good, j] = np.interp(k[~good], k[good], w[good, j])
    m = data.n_inputs
    return _replace_arrays(data, u=w[:, :m], y=w[:, m:]), int(mask.sum())
