"""The records every check of :mod:`sysid.quirks` works on: checked as every method checks its
data, each channel scaled by a power of two (exact: a grid stays a grid; every check is
invariant to a channel's scale), so that values of any magnitude :func:`sysid.data.as_flights`
lets through raise no overflow."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from sysid.data import IOData, as_flights

__all__ = ["records", "scaled"]


def records(flights: Sequence[IOData]) -> list[IOData]:
    """``flights`` checked as every method checks its data (:func:`sysid.data.as_flights`),
    each channel scaled by one power of two so that its largest magnitude over the records
    lies in [0.5, 1) (exact; every check is invariant to a channel's scale, and no square
    overflows): :func:`scaled`."""
    return scaled(flights)[0]


def scaled(flights: Sequence[IOData]) -> tuple[list[IOData], np.ndarray]:
    """``flights`` checked and scaled (:func:`records`), and each channel's binary exponent
    (m + l,) ints, columns as ``IOData.w``: ``np.ldexp(scaled, exponent)`` is the data."""
    recs = list(as_flights(flights))
    peak = np.max([np.abs(d.w).max(axis=0, initial=0.0) for d in recs], axis=0)
    exp = np.frexp(peak)[1].astype(int)
    if not exp.any():
        return recs, exp
    m = recs[0].n_inputs
    return [dataclasses.replace(d, u=np.ldexp(d.u, -exp[:m]), y=np.ldexp(d.y, -exp[m:]))
            for d in recs], exp
