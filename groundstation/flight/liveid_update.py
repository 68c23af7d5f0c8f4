"""One update of live identification as the views see it, and the rule that says the updates
have converged (the **Updates** and **Converged** paragraphs of
:mod:`groundstation.flight.liveid`).

Poles are ordered by descending magnitude, a conjugate pair with the negative imaginary part
first; the movement between two sets of poles is their Hausdorff distance: every pole within that
distance of one of the other set, and back.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Convergence", "Update", "converged", "finite_mean", "pole_move", "sorted_poles"]


@dataclass(frozen=True)
class Convergence:
    """Poles within ``tolerance`` (z-plane distance) over ``duration_s`` seconds of flight."""

    tolerance: float = 0.01
    duration_s: float = 3.0


@dataclass(frozen=True)
class Update:
    """One update as the views see it (the recorded row plus the arrays behind it)."""

    t: float
    n_samples: int
    span_s: float
    order: int
    poles: np.ndarray
    singular_values: np.ndarray
    fit_pct: float
    innovation_nvar: float
    pole_move: float
    update_s: float
    skipped: int
    final: bool
    fw_times: np.ndarray = field(repr=False)  # (k,) firmware s of the samples below
    host_times: np.ndarray = field(repr=False)  # (k,) the same on the flight clock (estimated)
    measured: np.ndarray = field(repr=False)  # (k, l) mean-removed outputs
    predicted: np.ndarray = field(repr=False)  # (k, l) their one-step predictions


def pole_move(a: np.ndarray, b: np.ndarray) -> float:
    """The Hausdorff distance between two sets of poles."""
    d = np.abs(a[:, None] - b[None, :])
    return float(max(d.min(axis=1).max(), d.min(axis=0).max()))


def finite_mean(x: np.ndarray) -> float:
    """The mean of the finite values of ``x`` (NaN if none)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    return float(x.mean()) if x.size else float("nan")


def sorted_poles(p: np.ndarray) -> np.ndarray:
    """Descending magnitude; a conjugate pair with the negative imaginary part first."""
    p = np.asarray(p, dtype=complex)
    return p[np.lexsort((np.round(p.imag, 12), -np.round(np.abs(p), 12)))]


def converged(conv: Convergence, history: Sequence[tuple[float, np.ndarray]], *, t: float,
              poles: np.ndarray) -> str:
    """Why the updates have converged at flight time ``t`` ('' while they have not): the
    current ``poles`` lie within ``conv.tolerance`` of those of every update of the last
    ``conv.duration_s`` seconds (``history``: flight time and poles of each update, the current
    one last), at least two of them older than the current one and one ``duration_s`` or more
    ago."""
    old = [i for i, (ti, _) in enumerate(history) if ti <= t - conv.duration_s]
    if not old or len(history) - old[-1] < 3:
        return ""
    moved = max(pole_move(poles, p) for _, p in history[old[-1]:])
    if not moved < conv.tolerance:  # NaN included
        return ""
    span = t - history[old[-1]][0]
    return (f"live id converged: poles moved at most {moved:.1e} "
            f"(< {conv.tolerance:g}) over {span:.1f} s")
