"""What a flight returns and the limits it is flown with (see :mod:`groundstation.flight`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.errors import FlightAborted

__all__ = ["FlightResult", "RateLimits", "block_summary"]

_FW_WRAP = 1 << 24  # log packets carry 24-bit firmware milliseconds


@dataclass(frozen=True)
class RateLimits:
    """Abort when ``|gyro|`` on any axis exceeds ``max_rate_deg_s`` (deg/s) for ``samples``
    consecutive log packets (20 ms each) while flying. 1000 deg/s is about three times the
    largest rate a ±25° PRBS step produces: a tumbling or crashed vehicle."""

    max_rate_deg_s: float = 1000.0
    samples: int = 3


@dataclass(frozen=True)
class FlightResult:
    """What :func:`fly_plan` returns: ``cause`` is ``""`` for a flight that ran to the end."""

    path: Path
    summary: dict[str, Any] = field(default_factory=dict)
    cause: str = ""

    @property
    def aborted(self) -> bool:
        return bool(self.cause)

    def raise_if_aborted(self) -> None:
        """One-line :class:`FlightAborted` naming the cause and the file."""
        if self.cause:
            raise FlightAborted(f"flight aborted: {self.cause}; session saved to {self.path}")


def block_summary(*, fw_ms: Sequence[int], period_s: float) -> dict[str, Any]:
    """Packets of one log block: received, expected from the firmware-time span
    :math:`\\lfloor (t_{last} - t_{first}) / T \\rceil + 1`, dropped from timestamp gaps
    (steps beyond 1.5 periods count :math:`\\mathrm{round}(\\Delta t / T) - 1`)."""
    ms = np.asarray(fw_ms, dtype=np.int64)
    if len(ms) < 2:
        return {"received": len(ms), "expected": len(ms), "dropped": 0}
    dt = np.diff(ms) % _FW_WRAP / 1000.0  # unwraps the 24-bit counter
    gaps = dt[dt > 1.5 * period_s]
    return {
        "received": len(ms),
        "expected": round(dt.sum() / period_s) + 1,
        "dropped": int(np.sum(np.round(gaps / period_s) - 1)),
    }
