"""**Frozen channels** (:func:`find_frozen`, :func:`frozen_warnings`): a measured signal with
noise never repeats one value exactly for long; a sensor that stopped, or a log block that
stopped while its last value was held onto the grid, does. Such a stretch is data the model must
explain as a plant at rest under a moving input: an identification from a record whose outputs
froze for its second half simulated its own validation badly, with no word of why (session 36's
degenerate-data review).

A channel is named when, in some record, one value repeats exactly over a run of at least
:data:`FROZEN_SHARE` of the record and :data:`FROZEN_MIN` samples, while the channel is
continuous elsewhere in the record (distinct values more than :data:`CONTINUOUS` of the other
samples: a PRBS, a step or a quantised sensor repeat values by design) and the run is not at
the record's smallest or largest value (a limit: saturation, not a freeze). Noise-free data at
rest (simulated) is named too, and the warning says so.

**Detrended data.** Exact equality survives the removal of a mean, but a linear detrend
(``--detrend linear``, :func:`sysid.preprocess.detrend_data` with ``kind="linear"``; the
records reach :func:`sysid.quirks.data_warnings` detrended) turns a frozen stretch into a
straight line, which went unnamed. A channel that looks linearly detrended (its least-squares
line is zero, within :data:`STRAIGHT_TOL` of its standard deviation) is searched for straight
stretches instead (second differences within :data:`STRAIGHT_TOL` of its range: noise never
is, to 1e-9); the line of such a stretch, taken off the whole channel, gives back the record
as logged up to a constant, and the same tests (run length, limit, continuous elsewhere) are
made on that, equality within rounding (:data:`STRAIGHT_TOL` of its range). Every other
channel is judged on exact equality, as before: a ramp in data that were not linearly
detrended is never named.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData, as_flights

__all__ = ["CONTINUOUS", "FROZEN_MIN", "FROZEN_SHARE", "STRAIGHT_TOL", "Frozen", "find_frozen",
           "frozen_warnings"]

#: A run of one value over at least this share of a record ...
FROZEN_SHARE = 0.1
#: ... and at least this many samples is a freeze ...
FROZEN_MIN = 50
#: ... in a channel whose distinct values are more than this share of the record's samples.
CONTINUOUS = 0.2
#: Rounding, as a share of a channel's spread, within which a linearly detrended channel's
#: least-squares line is zero and a stretch of it is straight (rounding is ~1e-14 of it at an
#: offset of 1e6 standard deviations; noise's second differences ~1e-4 of it).
STRAIGHT_TOL = 1e-9


@dataclass(frozen=True)
class Frozen:
    """One frozen stretch: ``name``, ``kind`` (``"input"``/``"output"``), ``unit``, the
    ``record`` (its source, or its index), the ``value`` held, the ``start`` sample and the
    ``length`` in samples of a record of ``n_samples`` at ``dt`` seconds."""

    name: str
    kind: str
    unit: str
    record: str
    value: float
    start: int
    length: int
    n_samples: int
    dt: float


def _runs(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Starts and lengths of the runs of exactly equal consecutive values of ``x``."""
    starts = np.concatenate([[0], np.flatnonzero(np.diff(x) != 0) + 1])
    return starts, np.diff(np.concatenate([starts, [len(x)]]))


def _linearly_detrended(x: np.ndarray, *, tol: float) -> bool:
    """Whether ``x`` (N,) has a zero least-squares line, to ``tol``: its mean and its line's
    change over the record (what a linear detrend leaves; a mean removal leaves the slope)."""
    k = np.arange(len(x)) - (len(x) - 1) / 2
    slope = float(k @ x) / float(k @ k) if len(x) > 1 else 0.0
    return abs(float(x.mean())) <= tol and abs(slope) * len(x) <= tol


def _straight_runs(x: np.ndarray, *, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Starts and lengths of the straight stretches of ``x`` (N,): second differences within
    ``tol``, at least 3 samples (a shorter run's lengths are its own, 1 or 2)."""
    starts, lengths = _runs(np.abs(np.diff(x, 2)) <= tol)
    line = np.abs(np.diff(x, 2))[starts] <= tol if len(x) > 2 else np.zeros(0, dtype=bool)
    return starts[line], lengths[line] + 2


def find_frozen(flights: Sequence[IOData]) -> list[Frozen]:
    """The longest frozen stretch of each channel of ``flights`` (records of one system,
    ``u`` (N, m), ``y`` (N, l)) that has one (module docstring), inputs first. In a linearly
    detrended channel ``value`` is the channel's value at ``start`` (the value as logged went
    with the trend)."""
    found = []
    for r, d in enumerate(as_flights(flights)):
        names = [*d.input_names, *d.output_names]
        units = [*d.input_units, *d.output_units]
        kinds = ["input"] * d.n_inputs + ["output"] * d.n_outputs
        n = d.n_samples
        need = max(FROZEN_MIN, int(np.ceil(FROZEN_SHARE * n)))
        if n < need:
            continue
        w = d.w
        for j in range(w.shape[1]):
            x = w[:, j]
            hit = _freeze(x, need=need)
            if hit is not None:
                start, length = hit
                found.append(Frozen(name=names[j], kind=kinds[j], unit=units[j],
                                    record=d.source or f"record {r + 1}",
                                    value=float(x[start]), start=start, length=length,
                                    n_samples=n, dt=d.dt))
    return found


def _freeze(x: np.ndarray, *, need: int) -> tuple[int, int] | None:
    """``(start, length)`` of the longest frozen stretch of channel ``x`` (N,) of at least
    ``need`` samples that is no limit, in a channel continuous elsewhere; None if none."""
    tol = STRAIGHT_TOL * float(np.ptp(x))
    detrended = tol > 0 and _linearly_detrended(x, tol=tol)
    starts, lengths = _straight_runs(x, tol=tol) if detrended else _runs(x)
    k = np.arange(len(x))
    for i in np.argsort(lengths)[::-1]:  # the longest run that is no limit
        start, length = int(starts[i]), int(lengths[i])
        if length < need:
            break
        level, q = x, 0.0
        if detrended:  # the run's line off the channel: the record as logged, to a constant
            slope = (x[start + length - 1] - x[start]) / (length - 1)
            level = x - slope * k
            q = STRAIGHT_TOL * float(np.ptp(level))
        held = level[start]
        if held - level.min() <= q or level.max() - held <= q:  # a limit, not a freeze
            continue
        rest = np.concatenate([level[:start], level[start + length:]])
        distinct = np.unique(rest if q == 0 else np.round(rest / q)).size
        if distinct > CONTINUOUS * len(rest):  # continuous elsewhere
            return start, length
        break
    return None


def frozen_warnings(flights: Sequence[IOData]) -> list[str]:
    """One line per frozen stretch (:func:`find_frozen`): where, how long, and the remedy.

    Parameters
    ----------
    flights : records of one system, ``u`` (N, m), ``y`` (N, l).

    Returns
    -------
    list of str, empty when nothing froze.
    """
    out = []
    for f in find_frozen(flights):
        out.append(f"{f.kind} {f.name} holds one value exactly for {f.length} samples "
                   f"({f.length * f.dt:.1f} s, {100 * f.length / f.n_samples:.0f} % of "
                   f"{f.record}) from sample {f.start} ({f.start * f.dt:.1f} s after that "
                   "record's start): a sensor or a log that stopped and was held, or data at "
                   "rest; if it stopped, leave that stretch out")
    return out
