"""Lock-step flights (``sim://...?speed=inf``): commander packets take effect a seeded per-flight
delay of 0-19 ms (+-1 ms per packet) after the simulation handles them, as over a radio link,
whose packets land at no fixed phase of the firmware's 50 Hz log clock.

Without it every setpoint of a lock-step flight lands at one phase (10-11 ms after a log sample),
which flatters a strictly proper motors -> gyro model identified from 50 Hz logs. Packets keep
their order. Used by :class:`groundstation.sim.simulator.Simulator`.
"""

from __future__ import annotations

import random
from collections import deque
from collections.abc import Iterator

__all__ = ["RADIO_PHASE_MS", "RadioPhase"]

RADIO_PHASE_MS = 20
"""The per-flight delay is drawn from [0, RADIO_PHASE_MS) ms."""


class RadioPhase:
    """Commander packets held for their radio delay (one simulation's; not thread-safe)."""

    def __init__(self, *, seed: int) -> None:
        self._rng = random.Random(seed * 104729 + 3)
        self._ms = self._rng.randrange(RADIO_PHASE_MS)
        self._held: deque[tuple[int, int, int, bytes]] = deque()  # (due ms, token, hdr, data)

    def hold(self, *, now_ms: int, token: int, header: int, data: bytes) -> None:
        """A commander packet handled at firmware ms ``now_ms``, held for its delay."""
        due = now_ms + max(0, self._ms + self._rng.choice((-1, 0, 1)))
        if self._held:
            due = max(due, self._held[-1][0])  # packets keep their order
        self._held.append((due, token, header, data))

    def next_due_ms(self) -> int | None:
        """Firmware ms the next held packet takes effect (``None``: none held)."""
        return self._held[0][0] if self._held else None

    def due(self, *, now_ms: int, flush: bool = False) -> Iterator[tuple[int, int, bytes]]:
        """``(token, header, data)`` of each packet whose delay has passed at ``now_ms``
        (``flush``: every one held), in order, each released as it is taken."""
        held = self._held
        while held and (flush or held[0][0] <= now_ms):
            _, token, header, data = held.popleft()
            yield token, header, data
