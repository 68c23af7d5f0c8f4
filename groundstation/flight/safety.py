"""The safety configuration a flight is flown with (see :mod:`groundstation.flight`)."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["RateLimits"]


@dataclass(frozen=True)
class RateLimits:
    """Abort when ``|gyro|`` on any axis exceeds ``max_rate_deg_s`` (deg/s) for ``samples``
    consecutive log packets (20 ms each) while flying. 1000 deg/s is about three times the
    largest rate a ±25° PRBS step produces: a tumbling or crashed vehicle."""

    max_rate_deg_s: float = 1000.0
    samples: int = 3
