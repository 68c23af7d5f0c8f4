r"""**Input directions that barely move** (:func:`find_weak_directions`,
:func:`direction_warnings`). Several inputs can be excited along fewer independent directions
than there are inputs: a roll-only flight moves the four motor commands along roll (and thrust,
with the altitude), while yaw, ``m1 - m2 + m3 - m4``, moves only with the controllers' answer
to disturbances. The data then say next to nothing of the response to that direction, and the
estimate of B along it is fitted to noise, which can cost the fit of every output: a roll-only
flight identified from its four motor commands simulated its own roll rate at -1.3 % (review,
2026-11-28), where a three-axis PRBS fits 70-90 %.

With each input's deviations from its record's mean scaled by its pooled standard deviation
(so units do not decide), the singular values :math:`\sigma_1 \ge \dots \ge \sigma_m` of the
stacked inputs measure the spread along each independent direction. A direction whose
:math:`\sigma_i / \sigma_1` is below :data:`DIRECTION_RATIO` (its variance under 1 % of the
strongest direction's) is named with its largest components. Measured: the simulator's
roll-only PRBS flight 1, 0.30, 0.115, 0.045 (the weakest: yaw); its three-axis PRBS 1, 1.00,
0.56, 0.42; the real CrazyPAD hover flights (controller commands) 1, 0.93, 0.85, 0.78.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData, as_flights

__all__ = ["DIRECTION_RATIO", "WeakDirection", "direction_warnings", "find_weak_directions"]

#: An input direction whose spread is below this share of the strongest one's barely moves.
DIRECTION_RATIO = 0.1
#: Components of a direction named in its warning: at least this weight (unit vector).
_NAMED_WEIGHT = 0.3


@dataclass(frozen=True)
class WeakDirection:
    """One input direction that barely moves: ``ratio`` its spread over the strongest
    direction's, ``weights`` ``(input name, weight)`` of its unit vector (inputs scaled by
    their standard deviations), in input order, its largest weight positive."""

    ratio: float
    weights: tuple[tuple[str, float], ...]


def find_weak_directions(flights: Sequence[IOData]) -> list[WeakDirection]:
    """The input directions of ``flights`` (records of one system, ``u`` (N, m)) whose spread
    is under :data:`DIRECTION_RATIO` of the strongest's (module docstring), weakest last; none
    for one input. Inputs that do not move at all are left out (other checks name them)."""
    recs = list(as_flights(flights))
    if recs[0].n_inputs < 2:
        return []
    dev = [d.u - d.u.mean(axis=0) for d in recs]
    n = sum(d.n_samples for d in recs)
    gram = sum(x.T @ x for x in dev) / n  # (m, m) covariance of the inputs
    spread = np.sqrt(np.diag(gram))
    moving = np.flatnonzero(spread > 0)
    if moving.size < 2:
        return []
    corr = gram[np.ix_(moving, moving)] / np.outer(spread[moving], spread[moving])
    values, vectors = np.linalg.eigh(corr)  # ascending
    sigma = np.sqrt(np.clip(values, 0.0, None))
    names = [recs[0].input_names[j] for j in moving]
    weak = []
    for i in range(moving.size - 1):
        ratio = float(sigma[i] / sigma[-1])
        if ratio >= DIRECTION_RATIO:
            break
        vec = vectors[:, i] * np.sign(vectors[np.argmax(np.abs(vectors[:, i])), i])
        weak.append(WeakDirection(ratio=ratio, weights=tuple(
            (name, float(w)) for name, w in zip(names, vec, strict=True))))
    return weak[::-1]


def _direction_text(d: WeakDirection) -> str:
    largest = max(abs(w) for _, w in d.weights)
    named = [(name, w) for name, w in d.weights if abs(w) >= min(_NAMED_WEIGHT, largest)]
    return " ".join(f"{'+' if w > 0 else '-'}{name}" for name, w in named)


def direction_warnings(flights: Sequence[IOData]) -> list[str]:
    """One line when some input directions barely move (:func:`find_weak_directions`)."""
    weak = find_weak_directions(flights)
    if not weak:
        return []
    m = len(weak[0].weights)  # the inputs that move (those that do not are named elsewhere)
    listed = "; ".join(f"{_direction_text(d)} ({d.ratio:.3f} of the strongest's spread)"
                       for d in reversed(weak))
    verb, them = ("moves", "it") if len(weak) == 1 else ("move", "them")
    k = m - len(weak)
    return [f"the {m} moving inputs move along {k} independent direction{'s' * (k != 1)}: "
            f"{listed} barely {verb} (under {DIRECTION_RATIO:g} of the strongest direction's "
            f"spread, inputs scaled by their standard deviations), so the response to {them} is "
            "fitted to noise and can cost the fit of every output; excite every direction the "
            "inputs span (a flight: a PRBS on every axis), or identify from inputs the record "
            "does excite (fewer inputs; for a roll-only flight's imported log: "
            "controller.cmd_roll)"]
