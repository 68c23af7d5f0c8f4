"""Clocks the flight runner schedules on.

A real flight uses the host's monotonic clock. A link driver whose peer keeps its own time (the
simulator runs faster than real time) registers a clock factory for its URI scheme, and
:func:`clock_for_uri` hands that clock to the runner, which never needs to know what is behind it.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Protocol, runtime_checkable

__all__ = ["Clock", "MonotonicClock", "clock_for_uri", "register_clock"]


@runtime_checkable
class Clock(Protocol):
    """Seconds on a monotonic time line, and a way to wait for a point on it."""

    speed: float
    """How many clock seconds pass per wall-clock second (1.0 for real time)."""

    def now(self) -> float:
        """Current time in seconds (arbitrary origin, never decreasing)."""
        ...

    def sleep_until(self, t: float) -> None:
        """Block until :meth:`now` >= ``t`` (returns at once if it already is)."""
        ...


class MonotonicClock:
    """The host's monotonic clock, for real flights."""

    speed = 1.0

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, t: float) -> None:
        while True:
            remaining = t - time.monotonic()
            if remaining <= 0:
                return
            # Sleep most of the way, then spin briefly: keeps deadline jitter well under 1 ms.
            time.sleep(remaining - 0.0005 if remaining > 0.002 else 0)


_factories: dict[str, Callable[[str], Clock | None]] = {}
_lock = threading.Lock()


def register_clock(scheme: str, factory: Callable[[str], Clock | None]) -> None:
    """Let URIs ``scheme://...`` be scheduled on ``factory(uri)`` (``None``: use the host clock)."""
    with _lock:
        _factories[scheme] = factory


def clock_for_uri(uri: str) -> Clock:
    """The clock a flight over ``uri`` should be scheduled on."""
    scheme = uri.split("://", 1)[0]
    with _lock:
        factory = _factories.get(scheme)
    clock = factory(uri) if factory is not None else None
    return clock if clock is not None else MonotonicClock()
