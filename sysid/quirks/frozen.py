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
the record's smallest or largest value (a limit: saturation, not a freeze). Exact equality
survives the removal of a mean but not of a trend: with ``--detrend linear`` a frozen stretch
is a straight line, and is not named. Noise-free data at rest (simulated) is named too, and
the warning says so.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData, as_flights

__all__ = ["CONTINUOUS", "FROZEN_MIN", "FROZEN_SHARE", "Frozen", "find_frozen",
           "frozen_warnings"]

#: A run of one value over at least this share of a record ...
FROZEN_SHARE = 0.1
#: ... and at least this many samples is a freeze ...
FROZEN_MIN = 50
#: ... in a channel whose distinct values are more than this share of the record's samples.
CONTINUOUS = 0.2


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


def find_frozen(flights: Sequence[IOData]) -> list[Frozen]:
    """The longest frozen stretch of each channel of ``flights`` (records of one system,
    ``u`` (N, m), ``y`` (N, l)) that has one (module docstring), inputs first."""
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
            starts, lengths = _runs(x)
            low, high = x.min(), x.max()
            for i in np.argsort(lengths)[::-1]:  # the longest run that is no limit
                start, length = int(starts[i]), int(lengths[i])
                if length < need:
                    break
                if x[start] in (low, high):
                    continue
                rest = np.concatenate([x[:start], x[start + length:]])
                if len(np.unique(rest)) > CONTINUOUS * len(rest):  # continuous elsewhere
                    found.append(Frozen(name=names[j], kind=kinds[j], unit=units[j],
                                        record=d.source or f"record {r + 1}",
                                        value=float(x[start]), start=start, length=length,
                                        n_samples=n, dt=d.dt))
                break
    return found


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
