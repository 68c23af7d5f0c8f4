r"""**Offsets** (:func:`find_offsets`, :func:`offset_warnings`). The methods fit no constant
term: a channel whose samples sit far from zero against their spread (an operating point: hover
thrust in PWM counts, a temperature in degrees, a sensor bias) is fitted as dynamics, a pole at
or near z = 1 whose transient runs through every simulation from a zero initial state. DaISy
thermic_res_wall's inputs (wall temperatures) sit 5 to 12 standard deviations from zero; given
to :func:`sysid.identify` as logged, the no-knobs model fits its validation third -33.5 % by
the benchmark protocol, against 72.3 % with the means removed.

A channel is named when the mean of some record lies more than :data:`OFFSET_SD` standard
deviations from zero (the deviations from each record's own mean, pooled over the records),
with the mean removal as the remedy (``sysid identify --detrend mean``, the command line's
default, or :func:`sysid.preprocess.detrend_data`). A step from rest (0, then 1 held for a
share ``a`` of the record) sits :math:`\sqrt{a / (1 - a)}` standard deviations from zero: not
named while the step holds for at most 90 % of the record (a step at mid-record: 1 SD), named
beyond (95 %: 4.4 SD). There the offset is part of the response, as the warning's last clause
says: the data already start at their operating point, and removing the mean would move it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData, as_flights

__all__ = ["OFFSET_SD", "Offset", "find_offsets", "offset_warnings"]

#: A record's mean this many (pooled) standard deviations from zero is an offset.
OFFSET_SD = 3.0


@dataclass(frozen=True)
class Offset:
    """One channel's offset: ``name``, ``kind`` (``"input"``/``"output"``), ``unit``, the
    ``mean`` (unit) of the record where it is largest and ``ratio``, that mean over the pooled
    standard deviation."""

    name: str
    kind: str
    unit: str
    mean: float
    ratio: float


def find_offsets(flights: Sequence[IOData]) -> list[Offset]:
    """The channels of ``flights`` (records of one system, ``u`` (N, m), ``y`` (N, l)) with
    an offset (module docstring), inputs first."""
    recs = list(as_flights(flights))
    means = np.array([d.w.mean(axis=0) for d in recs])  # (records, m + l)
    spread = np.sqrt(sum(((d.w - d.w.mean(axis=0)) ** 2).sum(axis=0) for d in recs)
                     / sum(d.n_samples for d in recs))
    first = recs[0]
    names = [*first.input_names, *first.output_names]
    units = [*first.input_units, *first.output_units]
    found = []
    for j in range(means.shape[1]):
        worst = int(np.argmax(np.abs(means[:, j])))
        mean = float(means[worst, j])
        if spread[j] > 0 and abs(mean) > OFFSET_SD * spread[j]:
            found.append(Offset(name=names[j], kind="input" if j < first.n_inputs else "output",
                                unit=units[j], mean=mean, ratio=abs(mean) / float(spread[j])))
    return found


def offset_warnings(flights: Sequence[IOData]) -> list[str]:
    """One line for all the channels with an offset (:func:`find_offsets`), or none."""
    found = find_offsets(flights)
    if not found:
        return []
    listed = ", ".join(f"{o.kind} {o.name} {o.mean:.4g}{(' ' + o.unit) if o.unit else ''} "
                       f"({o.ratio:.1f} SD)" for o in found)
    return [f"{len(found)} channel(s) sit far from zero against their spread: {listed}; the "
            "methods fit no constant, so an offset is fitted as dynamics (a pole at or near "
            "z = 1 and a transient in every simulation): remove the means (sysid identify "
            "--detrend mean, the command line's default; in Python "
            "sysid.preprocess.detrend_data) unless the offsets are part of the response"]
