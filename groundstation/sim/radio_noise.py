"""The air between the emulated Crazyradio and a simulated Crazyflie: which transmissions arrive,
what the dongle counts, and what a radio with that noise gives in theory.

Each transmission (a packet up, or its ack down) is lost, independently, by either of two causes:

* ``loss``: a fixed probability whatever the packet's length (a fade, a blocked path, a burst of
  interference);
* ``bit_error_rate``: every bit on air is flipped with this probability and a packet with a flipped
  bit is lost: an error in the address means the receiver never matches it, one in the packet
  control field, payload or CRC makes the 16-bit CRC fail. The Crazyflie's nRF51 drops a packet
  with a bad CRC without an ack (crazyflie2-nrf-firmware ``src/esb.c``: "Wrong CRC packet are
  dropped"), and the dongle's nRF24 counts an ack with a bad CRC as no ack; both cost a retry.
  An Enhanced ShockBurst packet of ``n`` payload bytes has ``65 + 8 n`` such bits (address 40,
  packet control field 9, CRC 16; the preamble only synchronises), so long packets fail more
  often than short ones, as on a real link. Corruptions the CRC misses (1 in 2^16) are ignored.

An attempt (packet and ack) gets through with ``p = through(up) * through(ack)``; with auto-retry
``ARC`` the dongle tries ``ARC + 1`` times, so a transfer is acked after ``k`` retries with
probability ``(1 - p)^k p`` (``k <= ARC``) and fails with ``(1 - p)^(ARC + 1)``
(:func:`retry_distribution`). cflib's link quality is ``10 (10 - k)`` averaged over acked
transfers (``cflib/crtp/radio_link_statistics.py``, 100 at a time); :func:`expected_link_quality`
and :func:`link_quality_sd` give its mean and the spread of one transfer's term, from which a test
derives the tolerance of a mean over ``N`` transfers (``z * sd / sqrt(N)``).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass, field

__all__ = ["OVERHEAD_BITS", "Air", "RadioNoise", "RadioStats", "expected_link_quality",
           "link_quality_sd", "retry_distribution"]

OVERHEAD_BITS = 40 + 9 + 16
"""Bits of an ESB packet besides its payload that a bit error makes it lose: address, packet
control field, CRC."""


@dataclass(frozen=True)
class RadioNoise:
    """How noisy the air is (both directions alike): ``loss`` per transmission and
    ``bit_error_rate`` per bit on air (see the module text)."""

    loss: float = 0.0
    bit_error_rate: float = 0.0

    def __post_init__(self) -> None:
        for name in ("loss", "bit_error_rate"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and 0.0 <= value <= 1.0):
                raise ValueError(f"{name} must be a number in [0, 1], got {value!r}")

    def p_intact(self, n_bytes: int) -> float:
        """Probability that a packet of ``n_bytes`` payload bytes has no bit error."""
        return (1.0 - self.bit_error_rate) ** (OVERHEAD_BITS + 8 * n_bytes)

    def p_through(self, n_bytes: int) -> float:
        """Probability that one transmission of ``n_bytes`` payload bytes arrives intact."""
        return (1.0 - self.loss) * self.p_intact(n_bytes)

    def p_attempt(self, *, up_bytes: int, ack_bytes: int) -> float:
        """Probability that one attempt gets its packet through and its ack back."""
        return self.p_through(up_bytes) * self.p_through(ack_bytes)


@dataclass
class RadioStats:
    """What the emulated dongle did: transfers (ack or failure, retries), and per transmission
    how many were sent, lost (``loss``) and corrupted (bit errors: CRC failures)."""

    transfers: int = 0
    acked: int = 0
    failed: int = 0
    retries: list[int] = field(default_factory=list)  # per transfer: retries, ARC if failed
    ok: list[bool] = field(default_factory=list)  # per transfer: acked
    transmissions: int = 0
    lost: int = 0
    corrupted: int = 0

    def link_quality(self) -> float:
        """cflib's link quality over these transfers: ``10 * (10 - mean retries)`` of the acked
        ones (cflib skips its statistics for a transfer without ack)."""
        acked = [r for r, ok in zip(self.retries, self.ok, strict=True) if ok]
        return 10.0 * (10.0 - sum(acked) / len(acked)) if acked else 0.0

    def histogram(self, *, arc: int) -> list[int]:
        """Transfers acked after 0, 1, ..., ``arc`` retries, then the failed ones (the order of
        :func:`retry_distribution`)."""
        counts = [0] * (arc + 2)
        for r, ok in zip(self.retries, self.ok, strict=True):
            counts[min(r, arc) if ok else arc + 1] += 1
        return counts


class Air:
    """Draws, from one seeded stream, whether each transmission arrives (and why not)."""

    def __init__(self, *, noise: RadioNoise, seed: int, stats: RadioStats) -> None:
        self.noise, self.stats = noise, stats
        self._rng = random.Random(seed * 7919 + 5)

    def through(self, n_bytes: int) -> bool:
        """One transmission of ``n_bytes`` payload bytes: whether it arrives intact."""
        noise, st = self.noise, self.stats
        st.transmissions += 1
        if noise.loss > 0.0 and self._rng.random() < noise.loss:
            st.lost += 1
            return False
        if noise.bit_error_rate > 0.0 and self._rng.random() >= noise.p_intact(n_bytes):
            st.corrupted += 1
            return False
        return True


def retry_distribution(*, p_attempt: float, arc: int = 3) -> list[float]:
    """Probabilities of a transfer acked after 0 .. ``arc`` retries, then of its failure."""
    miss = 1.0 - p_attempt
    return [miss**k * p_attempt for k in range(arc + 1)] + [miss ** (arc + 1)]


def _acked_retry_moments(*, p_attempt: float, arc: int) -> tuple[float, float]:
    dist = retry_distribution(p_attempt=p_attempt, arc=arc)[:-1]
    total = sum(dist)
    if total == 0.0:
        return math.nan, math.nan
    mean = sum(k * pk for k, pk in enumerate(dist)) / total
    var = sum((k - mean) ** 2 * pk for k, pk in enumerate(dist)) / total
    return mean, var


def expected_link_quality(*, p_attempt: float, arc: int = 3) -> float:
    """Mean of cflib's ``10 (10 - retries)`` over acked transfers whose attempts get through
    with ``p_attempt`` (loss only: ``p_attempt = (1 - loss)^2``; 98.9 at 5 %, 92.5 at 30 %)."""
    mean, _ = _acked_retry_moments(p_attempt=p_attempt, arc=arc)
    return 0.0 if math.isnan(mean) else 10.0 * (10.0 - mean)


def link_quality_sd(*, p_attempt: float, arc: int = 3) -> float:
    """Standard deviation of one acked transfer's ``10 (10 - retries)``: a mean over ``N``
    independent transfers spreads by ``link_quality_sd / sqrt(N)``."""
    _, var = _acked_retry_moments(p_attempt=p_attempt, arc=arc)
    return 0.0 if math.isnan(var) else 10.0 * math.sqrt(var)
