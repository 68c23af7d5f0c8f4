"""What a flight returns (see :mod:`groundstation.flight`; its limits: :mod:`.safety`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.errors import FlightAborted

__all__ = ["FlightResult", "block_summary", "setpoint_summary"]

_FW_WRAP = 1 << 24  # log packets carry 24-bit firmware milliseconds
LATENCY_ALLOWANCE_S = 0.05
"""Time a log packet may take to arrive: silence shorter than this plus one period before the
end of a flight is not a missing packet."""


@dataclass(frozen=True)
class FlightResult:
    """What :func:`fly_plan` returns: ``cause`` is ``""`` for a flight that ran to the end;
    ``escaped`` the ``SystemExit`` (or other exception that is no ``Exception``) a listener
    raised, which ended the flight, when ``fly_plan(reraise=False)`` returned it instead of
    raising it."""

    path: Path
    summary: dict[str, Any] = field(default_factory=dict)
    cause: str = ""
    escaped: BaseException | None = field(default=None, compare=False, repr=False)

    @property
    def aborted(self) -> bool:
        return bool(self.cause)

    def raise_if_aborted(self) -> None:
        """One-line :class:`FlightAborted` naming the cause and the file."""
        if self.cause:
            raise FlightAborted(f"flight aborted: {self.cause}; session saved to {self.path}")


def block_summary(*, fw_ms: Sequence[int], period_s: float,
                  silence_s: float = 0.0) -> dict[str, Any]:
    """Packets of one log block: received, expected from the firmware-time span
    :math:`\\lfloor (t_{last} - t_{first}) / T \\rceil + 1`, dropped from timestamp gaps
    (steps beyond 1.5 periods count :math:`\\mathrm{round}(\\Delta t / T) - 1`), plus
    ``missing_at_end``: the packets due in the ``silence_s`` seconds (host clock) from the last
    one received to the end of the flight, less :data:`LATENCY_ALLOWANCE_S` (a link that died
    before the end; counted in ``expected`` and ``dropped`` too)."""
    ms = np.asarray(fw_ms, dtype=np.int64)
    tail = max(0, int((silence_s - LATENCY_ALLOWANCE_S) / period_s)) if len(ms) else 0
    if len(ms) < 2:
        return {"received": len(ms), "expected": len(ms) + tail, "dropped": tail,
                "missing_at_end": tail}
    dt = np.diff(ms) % _FW_WRAP / 1000.0  # unwraps the 24-bit counter
    gaps = dt[dt > 1.5 * period_s]
    expected = round(dt.sum() / period_s) + 1
    # a gap the packets after it make up for is timestamp jitter, not a loss (SITL: "563 /
    # 563 packets, 1 dropped"): never more dropped than the count is short
    dropped = min(int(np.sum(np.round(gaps / period_s) - 1)), max(0, expected - len(ms)))
    return {
        "received": len(ms),
        "expected": expected + tail,
        "dropped": dropped + tail,
        "missing_at_end": tail,
    }


def setpoint_summary(*, sent_t: Sequence[float], period_s: float, scheduled: int,
                     planned: int, stopped: bool = False,
                     after_stop: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Setpoints sent on the grid (flight times ``sent_t``, s: the plan's, the thrust-lock
    release, an abort's descent), scheduled and planned, whether the stop setpoint (sent and
    recorded apart, repeated until delivered) was delivered, how it was fed after
    (``after_stop``: setpoints, seconds, why it ended; empty when not fed) and the jitter of
    the send period against ``period_s`` in ms (p50, p99, max)."""
    dt = np.diff(np.asarray(sent_t, dtype=float))
    jitter = np.abs(dt - period_s) * 1000.0 if len(dt) else np.zeros(1)
    return {"sent": len(sent_t), "scheduled": scheduled, "planned": planned,
            "stopped": stopped, "after_stop": dict(after_stop or {}), "period_s": period_s,
            "jitter_ms": {"p50": round(float(np.percentile(jitter, 50)), 3),
                          "p99": round(float(np.percentile(jitter, 99)), 3),
                          "max": round(float(jitter.max()), 3)}}
