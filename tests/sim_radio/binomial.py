"""Tolerances from the spread of the counts themselves, for checks of injected radio noise.

A count of ``n`` independent events of probability ``p`` spreads by ``sqrt(n p (1 - p))``; a mean
of ``n`` independent terms of standard deviation ``sd`` by ``sd / sqrt(n)``. The checks allow
:data:`Z` of those: a correct emulation fails one check in about 16 000 (two-sided normal tail at
4 sigma), a wrong probability of a few per cent of ``p`` fails at the counts these tests make.
The emulation's draws are seeded, but which draw meets which packet depends on thread timing, so
each run is a fresh sample.
"""

from __future__ import annotations

import math

Z = 4.0


def check_count(count: int, *, n: int, p: float, what: str) -> None:
    """``count`` of ``n`` trials is within :data:`Z` binomial sigmas of ``n p``."""
    sigma = math.sqrt(n * p * (1.0 - p))
    tol = Z * sigma + 0.5  # half a count: a spread below one event still allows the integer
    assert abs(count - n * p) <= tol, (
        f"{what}: {count} of {n}, expected {n * p:.1f} +- {tol:.1f} (p = {p:.4g})")


def check_mean(mean: float, *, n: int, expected: float, sd: float, what: str) -> None:
    """A mean of ``n`` independent terms of spread ``sd`` is within :data:`Z` sigmas of
    ``expected``."""
    tol = Z * sd / math.sqrt(n)
    assert abs(mean - expected) <= tol, (
        f"{what}: {mean:.3f} over {n}, expected {expected:.3f} +- {tol:.3f}")
