"""Quirks of the data that mislead a selection, each in its module: gross outliers
(:mod:`sysid.quirks.outliers`), a drift, a linear trend (:mod:`sysid.quirks.drift`), a
quantised output (:mod:`sysid.quirks.quantised`), channels far from zero
(:mod:`sysid.quirks.offsets`), a channel that froze (:mod:`sysid.quirks.frozen`) and input
directions that barely move (:mod:`sysid.quirks.directions`).
:func:`data_warnings` gives them as one-line warnings, for a selection's report
(:func:`sysid.auto.select` calls it on all its records) and for ``sysid identify`` with its
settings given.

**Magnitudes**: the checks take the records through :func:`sysid.data.as_flights`, which
refuses, in one line, a channel whose values would overflow or underflow the sums of squares an
identification forms (:func:`sysid.data.check_magnitudes`); what it lets through raises no
overflow here either (tested at 1e140 and 1e-140).
"""

from __future__ import annotations

from collections.abc import Sequence

from sysid.data import IOData, as_flights
from sysid.quirks.directions import (
    DIRECTION_RATIO,
    WeakDirection,
    direction_warnings,
    find_weak_directions,
)
from sysid.quirks.drift import AR_ORDER, DRIFT_RATIO, DRIFT_T, drift_warnings, trend_ratios
from sysid.quirks.frozen import FROZEN_MIN, FROZEN_SHARE, Frozen, find_frozen, frozen_warnings
from sysid.quirks.offsets import OFFSET_SD, Offset, find_offsets, offset_warnings
from sysid.quirks.outliers import (
    FALSE_ALARM,
    MAX_LAG,
    MIN_THRESHOLD,
    Outliers,
    find_outliers,
    outlier_masks,
    outlier_threshold,
    outlier_warnings,
)
from sysid.quirks.quantised import (
    QUANT_DISTINCT,
    QUANT_NOISE,
    Quantised,
    find_quantised,
    quantisation_warnings,
)

__all__ = [
    "AR_ORDER",
    "DIRECTION_RATIO",
    "DRIFT_RATIO",
    "DRIFT_T",
    "FALSE_ALARM",
    "FROZEN_MIN",
    "FROZEN_SHARE",
    "MAX_LAG",
    "MIN_THRESHOLD",
    "OFFSET_SD",
    "QUANT_DISTINCT",
    "QUANT_NOISE",
    "Frozen",
    "Offset",
    "Outliers",
    "Quantised",
    "WeakDirection",
    "data_warnings",
    "direction_warnings",
    "drift_warnings",
    "find_frozen",
    "find_offsets",
    "find_outliers",
    "find_quantised",
    "find_weak_directions",
    "frozen_warnings",
    "offset_warnings",
    "outlier_masks",
    "outlier_threshold",
    "outlier_warnings",
    "quantisation_warnings",
    "trend_ratios",
]


def data_warnings(flights: Sequence[IOData]) -> list[str]:
    """The data's quirks that mislead a selection, one line each: offsets
    (:func:`offset_warnings`), frozen stretches (:func:`frozen_warnings`), outliers
    (:func:`outlier_warnings`), then drifts (:func:`drift_warnings`), then quantised outputs
    (:func:`quantisation_warnings`), then input directions that barely move
    (:func:`direction_warnings`).

    Parameters
    ----------
    flights : the identification records of one system, each ``u`` (N, m), ``y`` (N, l).

    Returns
    -------
    list of str, empty for clean data.
    """
    recs = list(as_flights(flights))
    return [*offset_warnings(recs), *frozen_warnings(recs), *outlier_warnings(recs),
            *drift_warnings(recs), *quantisation_warnings(flights), *direction_warnings(recs)]
