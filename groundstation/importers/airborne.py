"""Airborne segments of an imported log: when the vehicle flew, from thrust and height.

:func:`airborne_segments` is a pure function of aligned arrays; :func:`find_segments` picks the
thrust and height variables from imported log blocks and calls it. The rule, the variables and
the phase names the importer gives the segments (``airborne-1``, ...) are in
``docs/session-format.md`` ("How airborne segments are found").
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

__all__ = ["HEIGHT_SOURCES", "THRUST_SOURCES", "Segment", "airborne_segments", "find_segments"]

ON_THRUST = 10_000.0
"""Motors on at or above this thrust (PWM scale 0-65535): a Crazyflie 2.x idles at 0."""

THRUST_SOURCES: tuple[tuple[str, ...], ...] = (
    ("controller.cmd_thrust",),
    ("stabilizer.thrust",),
    ("controller.actuatorThrust",),
    ("motor.m1", "motor.m2", "motor.m3", "motor.m4"),
    ("pwm.m1_pwm", "pwm.m2_pwm", "pwm.m3_pwm", "pwm.m4_pwm"),
)
"""Thrust signals, first found wins; several variables are averaged."""

HEIGHT_SOURCES: tuple[tuple[str, float], ...] = (
    ("stateEstimate.z", 1.0),
    ("kalman.stateZ", 1.0),
    ("stateEstimateZ.z", 1e-3),
    ("range.zrange", 1e-3),
)
"""Height signals with their scale to metres, first found wins."""


@dataclass(frozen=True)
class Segment:
    """One airborne stretch, ``[start_s, end_s]`` on the log's clock."""

    start_s: float
    end_s: float


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``[i0, i1)`` index ranges where ``mask`` is True."""
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                    strict=True))


def _close_gaps(mask: np.ndarray, t: np.ndarray, *, max_gap_s: float) -> np.ndarray:
    """``mask`` with False runs shorter than ``max_gap_s`` between True runs set True (a thrust
    dropout of a few samples is not a landing)."""
    out = mask.copy()
    for i0, i1 in _runs(~mask):
        if i0 > 0 and i1 < len(mask) and t[i1] - t[i0 - 1] <= max_gap_s:
            out[i0:i1] = True
    return out


def _ground_level(height: np.ndarray, on: np.ndarray, i0: int, t: np.ndarray,
                  run_h: np.ndarray) -> float:
    """Median height with motors off in the 2 s before index ``i0``; else over every motors-off
    sample; else the run's 5th percentile."""
    before = (~on[:i0]) & (t[:i0] >= t[i0] - 2.0) & np.isfinite(height[:i0])
    if before.any():
        return float(np.median(height[:i0][before]))
    off = (~on) & np.isfinite(height)
    if off.any():
        return float(np.median(height[off]))
    return float(np.nanpercentile(run_h, 5))


def airborne_segments(
    *,
    t_s: np.ndarray,
    thrust: np.ndarray,
    height_m: np.ndarray | None = None,
    on_thrust: float = ON_THRUST,
    min_height_m: float = 0.10,
    height_fraction: float = 0.5,
    guard_s: float = 0.75,
    no_height_guard_s: float = 1.0,
    min_duration_s: float = 1.0,
) -> list[Segment]:
    """Airborne segments of one log (rule in the module docstring and the session-format doc).

    ``t_s``, ``thrust`` and ``height_m`` are shape ``(n,)`` on one clock (seconds, not
    decreasing); NaN thrust counts as motors off and NaN height as on the ground.
    """
    t = np.asarray(t_s, dtype=np.float64)
    f = np.asarray(thrust, dtype=np.float64)
    if t.ndim != 1 or f.shape != t.shape:
        raise ValueError(f"t_s and thrust must be (n,) alike, got {t.shape} and {f.shape}")
    h = None if height_m is None else np.asarray(height_m, dtype=np.float64)
    if h is not None and h.shape != t.shape:
        raise ValueError(f"height_m must be shaped like t_s {t.shape}, got {h.shape}")
    if len(t) < 2 or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        return []
    on = _close_gaps(np.isfinite(f) & (f >= on_thrust), t, max_gap_s=0.25)
    spans: list[tuple[float, float]] = []
    for i0, i1 in _runs(on):
        if h is None or not np.isfinite(h[i0:i1]).any():
            spans.append((t[i0] + no_height_guard_s, t[i1 - 1] - no_height_guard_s))
            continue
        run_h = h[i0:i1] - _ground_level(h, on, i0, t, h[i0:i1])
        top = float(np.nanpercentile(run_h, 90))
        if top < min_height_m:
            continue  # motors ran, the vehicle did not leave the ground
        level = max(min_height_m, height_fraction * top)
        known = np.where(np.isfinite(run_h), run_h, -np.inf)
        up = known >= level
        for a0, a1 in _runs(known >= min_height_m):  # clear of the ground: a dip is no landing
            high = np.flatnonzero(up[a0:a1])
            if len(high):
                spans.append((t[i0 + a0 + high[0]] + guard_s, t[i0 + a0 + high[-1]] - guard_s))
    return [Segment(float(a), float(b)) for a, b in spans if b - a >= min_duration_s]


class _Block(Protocol):
    """What :func:`find_segments` needs of a log block (``ImportedBlock`` has it)."""

    @property
    def timestamps_s(self) -> np.ndarray: ...

    @property
    def values(self) -> Mapping[str, np.ndarray]: ...


def _first_thrust(blocks: Sequence[_Block]) -> tuple[_Block, tuple[str, ...]] | None:
    for names in THRUST_SOURCES:
        for b in blocks:
            if all(n in b.values for n in names):
                return b, names
    return None


def _height_on(blocks: Sequence[_Block], t: np.ndarray) -> tuple[np.ndarray, str] | None:
    """The first height source, in metres, on the times ``t`` (NaN outside its span)."""
    for name, scale in HEIGHT_SOURCES:
        for b in blocks:
            if name not in b.values:
                continue
            ht = np.asarray(b.timestamps_s, dtype=np.float64)
            hv = np.asarray(b.values[name], dtype=np.float64) * scale
            ok = np.isfinite(ht) & np.isfinite(hv)
            ht, hv = ht[ok], hv[ok]
            if len(ht) < 2:
                continue
            order = np.argsort(ht, kind="stable")
            ht, hv = ht[order], hv[order]
            out = np.interp(t, ht, hv)
            out[(t < ht[0]) | (t > ht[-1])] = np.nan
            return out, name
    return None


def find_segments(blocks: Sequence[_Block]) -> tuple[list[Segment], str]:
    """Airborne segments of imported ``blocks`` and one sentence saying how they were found."""
    found = _first_thrust(blocks)
    if found is None:
        wanted = ", ".join(n[0] for n in THRUST_SOURCES)
        return [], f"no airborne segments: no thrust logged (looked for {wanted})"
    block, names = found
    t = np.asarray(block.timestamps_s, dtype=np.float64)
    with np.errstate(all="ignore"):
        thrust = np.mean([np.asarray(block.values[n], dtype=np.float64) for n in names], axis=0)
    height = _height_on(blocks, t)
    thrust_text = names[0] if len(names) == 1 else f"the mean of {', '.join(names)}"
    how = f"thrust {thrust_text}" + (f", height {height[1]}" if height else ", no height logged")
    if len(t) > 1 and (not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0)):
        return [], f"no airborne segments: the times of the thrust block go backwards ({how})"
    segments = airborne_segments(t_s=t, thrust=thrust,
                                 height_m=None if height is None else height[0])
    if not segments:
        return [], f"no airborne segments found ({how})"
    spans = ", ".join(f"{s.start_s:.2f}-{s.end_s:.2f} s" for s in segments)
    return segments, f"{len(segments)} airborne segment(s) from {how}: {spans}"
