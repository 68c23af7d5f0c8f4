"""**Frozen channels** (:func:`find_frozen`, :func:`frozen_warnings`): a measured signal with
noise never repeats one value exactly for long; a sensor that stopped, or a log block that
stopped while its last value was held onto the grid, does. Such a stretch is data the model must
explain as a plant at rest under a moving input: an identification from a record whose outputs
froze for its second half simulated its own validation badly, with no word of why (session 36's
degenerate-data review).

A channel is named when, in some record, one value repeats exactly over a run of at least
:data:`FROZEN_SHARE` of the record and :data:`FROZEN_MIN` samples, while the channel is
continuous there (distinct values more than :data:`CONTINUOUS` of the samples: a PRBS, a step
or a quantised sensor repeat values by design) and the run is not at the record's smallest or
largest value (a limit: saturation, not a freeze).
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


def _longest_run(x: np.ndarray) -> tuple[int, int]:
    """Start and length of the longest run of exactly equal consecutive values of ``x``."""
    change = np.flatnonzero(np.diff(x) != 0) + 1
    starts = np.concatenate([[0], change])
    lengths = np.diff(np.concatenate([starts, [len(x)]]))
    i = int(np.argmax(lengths))
    return int(starts[i]), int(lengths[i])


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
            start, length = _longest_run(x)
            held = x[start]
            if (length < need or held in (x.min(), x.max())
                    or len(np.unique(x)) <= CONTINUOUS * n):
                continue
            found.append(Frozen(name=names[j], kind=kinds[j], unit=units[j],
                                record=d.source or f"record {r + 1}", value=float(held),
                                start=start, length=length, n_samples=n, dt=d.dt))
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
        unit = f" {f.unit}" if f.unit else ""
        out.append(f"{f.kind} {f.name} holds {f.value:.6g}{unit} exactly for {f.length} samples "
                   f"({f.length * f.dt:.3g} s, {100 * f.length / f.n_samples:.0f} % of "
                   f"{f.record}) from {f.start * f.dt:.3g} s into it: a sensor or a log that "
                   "stopped, its last value held; leave that stretch out (--window)")
    return out
