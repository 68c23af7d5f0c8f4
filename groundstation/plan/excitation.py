"""Excitation signals for identification experiments: PRBS, doublets, steps, chirps.

Pure numpy. Every generator returns a 1-D array of shape ``(n_samples,)`` (one input channel);
stack channels with ``np.column_stack`` to get the house layout ``(n_samples, n_channels)``.

Maximal-length PRBS
-------------------
A binary sequence :math:`a_k \\in \\{0, 1\\}` from a linear feedback shift register of length
:math:`n` with taps :math:`T` (:data:`LFSR_TAPS`) obeys the recurrence

.. math::  a_k = \\bigoplus_{t \\in T} a_{k-t}, \\qquad k \\ge n,

whose characteristic polynomial :math:`x^n + \\sum_{t \\in T} x^{n-t}` is primitive over GF(2),
so the sequence has the maximal period :math:`N = 2^n - 1` (an *m-sequence*). The *seed* is the
initial register state: the first :math:`n` chips are its bits, least significant first
(:math:`a_k = (\\text{seed} \\gg k) \\,\\&\\, 1` for :math:`k < n`); every non-zero seed lies on
the same cycle, so two seeds give the same sequence shifted by :func:`prbs_shift` chips.

The signal :math:`u_k = A\\,(2 a_{\\lfloor k/P \\rfloor} - 1)` holds each chip for the *clock
period* :math:`P` samples. Over one period it has

* balance: :math:`2^{n-1}` chips at :math:`+A` and :math:`2^{n-1} - 1` at :math:`-A`;
* two-valued periodic autocorrelation (chip level, :math:`A = 1`):
  :math:`R(0) = N`, :math:`R(\\tau) = -1` for :math:`\\tau \\not\\equiv 0 \\pmod N`;
* persistence of excitation of order :math:`N P - P + 1` (:func:`prbs_persistence_order`):
  the periodic spectrum of the held sequence has :math:`NP` lines, of which the hold's zeros
  remove the :math:`P - 1` at multiples of :math:`1/(P\\,\\text{dt})` other than DC.
"""

from __future__ import annotations

import math

import numpy as np

from groundstation.errors import PlanError

__all__ = [
    "LFSR_TAPS",
    "ExcitationError",
    "advance_state",
    "chirp",
    "doublet",
    "mls_bits",
    "prbs",
    "prbs_period",
    "prbs_persistence_order",
    "prbs_shift",
    "register_length_for_period",
    "step",
]


class ExcitationError(PlanError):
    """Excitation parameters that cannot be honoured (one line, says what to change)."""


LFSR_TAPS: dict[int, tuple[int, ...]] = {
    2: (2, 1), 3: (3, 2), 4: (4, 3), 5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4),
    9: (9, 5), 10: (10, 7), 11: (11, 9), 12: (12, 11, 10, 4), 13: (13, 12, 11, 8),
    14: (14, 13, 12, 2), 15: (15, 14), 16: (16, 15, 13, 4), 17: (17, 14), 18: (18, 11),
    19: (19, 18, 17, 14), 20: (20, 17), 21: (21, 19), 22: (22, 21), 23: (23, 18),
    24: (24, 23, 22, 17),
}  # fmt: skip
"""Register length n -> feedback taps of a maximal-length (Fibonacci) LFSR.

The taps are the exponents of the primitive trinomials / pentanomials
:math:`x^n + x^{t_2} + \\dots + 1` tabulated by Xilinx (XAPP052) and Wikipedia's "Linear-feedback
shift register"; ``tests/plan/test_excitation.py`` proves each one primitive.
"""


def _check_register_length(register_length: int) -> None:
    if register_length not in LFSR_TAPS:
        raise ExcitationError(
            f"PRBS register_length {register_length!r} is not supported; "
            f"use an integer from {min(LFSR_TAPS)} to {max(LFSR_TAPS)}"
        )


def _check_seed(register_length: int, seed: int) -> None:
    top = (1 << register_length) - 1
    if not isinstance(seed, int | np.integer) or not 1 <= seed <= top:
        raise ExcitationError(
            f"PRBS seed {seed!r} is not a non-zero {register_length}-bit register state; "
            f"use an integer from 1 to {top}"
        )


def mls_bits(*, register_length: int, seed: int = 1, n_chips: int | None = None) -> np.ndarray:
    """The m-sequence :math:`a_k` as ``uint8`` 0/1 chips, shape ``(n_chips,)``.

    ``n_chips`` defaults to one period :math:`2^n - 1`; longer requests continue the sequence
    periodically. The recurrence is evaluated in blocks of ``min(taps)`` chips at a time, which
    is exact because no tap reaches into the block being computed.
    """
    _check_register_length(register_length)
    _check_seed(register_length, seed)
    period = (1 << register_length) - 1
    n_chips = period if n_chips is None else int(n_chips)
    if n_chips < 0:
        raise ExcitationError(f"PRBS n_chips {n_chips} is negative; ask for 0 or more chips")
    n_gen = min(n_chips, period)
    taps = LFSR_TAPS[register_length]
    block = min(taps)
    a = np.zeros(max(n_gen, register_length), dtype=np.uint8)
    a[:register_length] = [(int(seed) >> i) & 1 for i in range(register_length)]
    for k in range(register_length, n_gen, block):
        stop = min(k + block, n_gen)
        acc = a[k - taps[0] : stop - taps[0]].copy()
        for t in taps[1:]:
            acc ^= a[k - t : stop - t]
        a[k:stop] = acc
    a = a[:n_gen]
    if n_chips > period:
        a = np.resize(a, n_chips)  # periodic continuation
    return a


def prbs(
    *,
    n_samples: int,
    register_length: int,
    clock_period: int = 1,
    amplitude: float = 1.0,
    seed: int = 1,
) -> np.ndarray:
    """Maximal-length PRBS :math:`u_k = A(2a_{\\lfloor k/P\\rfloor} - 1)`, shape ``(n_samples,)``.

    ``clock_period`` P is in samples (each chip is held P samples); the output is ``float64``
    with values exactly ``+amplitude`` / ``-amplitude``. The period is :func:`prbs_period`.
    """
    if not isinstance(clock_period, int | np.integer) or clock_period < 1:
        raise ExcitationError(
            f"PRBS clock_period {clock_period!r} is not a positive whole number of samples"
        )
    n_chips = -(-int(n_samples) // int(clock_period))
    bits = mls_bits(register_length=register_length, seed=seed, n_chips=n_chips)
    chips = np.where(bits == 1, float(amplitude), -float(amplitude))
    return np.repeat(chips, int(clock_period))[: int(n_samples)]


def prbs_period(*, register_length: int, clock_period: int = 1) -> int:
    """Period of the held PRBS in samples: :math:`(2^n - 1)\\,P`."""
    _check_register_length(register_length)
    return ((1 << register_length) - 1) * int(clock_period)


def prbs_persistence_order(*, register_length: int, clock_period: int = 1) -> int:
    """Order of persistence of excitation of the held PRBS: :math:`N P - P + 1`, N = 2^n - 1.

    A signal is persistently exciting of order L when its L x L autocovariance matrix is
    positive definite; for a periodic signal that order is the number of non-zero lines of its
    periodic spectrum. The m-sequence has all N lines non-zero (|X_0| = 1, |X_k| = sqrt(N + 1));
    holding each chip P samples multiplies the NP-point spectrum by the hold's transfer
    function, which vanishes at the P - 1 non-zero multiples of N.
    """
    n_period = prbs_period(register_length=register_length, clock_period=clock_period)
    return n_period - int(clock_period) + 1


def register_length_for_period(period: int) -> int:
    """The register length n with :math:`2^n - 1` = ``period`` chips (an error if none)."""
    for n in LFSR_TAPS:
        if (1 << n) - 1 == period:
            return n
    valid = ", ".join(str((1 << n) - 1) for n in list(LFSR_TAPS)[:9])
    raise ExcitationError(
        f"PRBS period {period!r} chips is not 2^n - 1; use one of {valid}, ... "
        f"(up to {(1 << max(LFSR_TAPS)) - 1})"
    )


def _apply(matrix: list[int], state: int) -> int:
    """A GF(2) linear map (``matrix[i]``: the image of bit i) applied to a register state."""
    out = 0
    for i, column in enumerate(matrix):
        if state >> i & 1:
            out ^= column
    return out


def _step_matrix(register_length: int) -> list[int]:
    """The LFSR's one-chip step on the register state (the next n chips, least significant
    first): shift right, the feedback bit :math:`a_{k+n} = \\bigoplus_t a_{k+n-t}` on top."""
    n, fed = register_length, {register_length - t for t in LFSR_TAPS[register_length]}
    return [(1 << i >> 1) | ((i in fed) << (n - 1)) for i in range(n)]


def advance_state(*, register_length: int, seed: int, chips: int) -> int:
    """The register state ``chips`` chips after ``seed`` (``chips`` >= 0, any size): the step
    raised to that power by squaring, so a 24-bit register jumps 16 million chips at once."""
    _check_register_length(register_length)
    _check_seed(register_length, seed)
    state, power = int(seed), _step_matrix(register_length)
    for bit in bin(int(chips) % ((1 << register_length) - 1))[:1:-1]:
        if bit == "1":
            state = _apply(power, state)
        power = [_apply(power, column) for column in power]
    return state


def prbs_shift(*, register_length: int, seed_a: int, seed_b: int) -> int:
    """Chips d in [0, N) such that the sequence from ``seed_b`` is the one from ``seed_a``
    advanced by d: :math:`b_k = a_{k+d}`.

    Two axes driven by seeds whose shift d (and N - d) exceeds the longest lag that matters
    (the identification horizons) are uncorrelated at every such lag: over a full period the
    cross-correlation is :math:`-1/N` except at lag d.

    Baby steps, giant steps: the states of the m = ceil(sqrt(N)) chips from ``seed_b`` are
    tabled, and ``seed_a`` advanced m chips at a time until it lands on one; about
    :math:`2\\sqrt{N}` steps (8 200 for a 24-bit register, whose period is 16.8 million chips).
    """
    _check_seed(register_length, seed_a)
    _check_seed(register_length, seed_b)
    n, period = register_length, (1 << register_length) - 1
    m = math.isqrt(period - 1) + 1
    b = mls_bits(register_length=n, seed=seed_b, n_chips=m + n - 1).astype(np.int64)
    windows = np.zeros(m, dtype=np.int64)
    for i in range(n):
        windows |= b[i : i + m] << i
    baby = {int(w): j for j, w in reversed(list(enumerate(windows)))}  # the first j of a state
    giant = [advance_state(register_length=n, seed=1 << i, chips=m) for i in range(n)]
    state = int(seed_a)
    for i in range(m + 1):
        if state in baby:  # state_{i m}(a) = state_j(b), so b starts i m - j chips into a
            return (i * m - baby[state]) % period
        state = _apply(giant, state)
    raise AssertionError("every non-zero state lies on the m-sequence's one cycle")


def _check_count(name: str, value: int) -> int:
    if not isinstance(value, int | np.integer) or value < 0:
        raise ExcitationError(f"{name} {value!r} is not a whole number of samples >= 0")
    return int(value)


def doublet(*, n_samples: int, width: int, amplitude: float, start: int = 0) -> np.ndarray:
    """Doublet: ``+amplitude`` for ``width`` samples from ``start``, then ``-amplitude`` for
    ``width`` samples, zero elsewhere; shape ``(n_samples,)``."""
    n = _check_count("n_samples", n_samples)
    width = _check_count("doublet width", width)
    start = _check_count("doublet start", start)
    if width == 0 or start + 2 * width > n:
        raise ExcitationError(
            f"doublet of width {width} from sample {start} needs {start + 2 * width} samples "
            f"but only {n} are available; shorten width/start or lengthen the signal"
        )
    u = np.zeros(n)
    u[start : start + width] = amplitude
    u[start + width : start + 2 * width] = -amplitude
    return u


def step(*, n_samples: int, amplitude: float, start: int = 0) -> np.ndarray:
    """Step: zero before sample ``start``, ``amplitude`` from it on; shape ``(n_samples,)``."""
    n = _check_count("n_samples", n_samples)
    start = _check_count("step start", start)
    if start >= n:
        raise ExcitationError(
            f"step start {start} is not before the end of the signal ({n} samples); move it earlier"
        )
    u = np.zeros(n)
    u[start:] = amplitude
    return u


def chirp(
    *,
    n_samples: int,
    dt: float,
    f_start: float,
    f_end: float,
    amplitude: float,
    sweep: str = "linear",
) -> np.ndarray:
    """Frequency sweep :math:`u_k = A \\sin\\varphi(t_k)`, :math:`t_k = k\\,dt`, shape ``(n,)``.

    With :math:`T = n\\,dt`: linear :math:`\\varphi = 2\\pi(f_0 t + (f_1 - f_0) t^2 / 2T)`;
    logarithmic :math:`\\varphi = 2\\pi f_0 T (r^{t/T} - 1) / \\ln r`, :math:`r = f_1 / f_0`.
    Frequencies in Hz, ``dt`` in s; ``f_end`` must stay below Nyquist :math:`1 / 2dt`.
    """
    n = _check_count("n_samples", n_samples)
    nyquist = 0.5 / dt
    for name, f in (("f_start", f_start), ("f_end", f_end)):
        if not 0 <= f < nyquist:
            raise ExcitationError(
                f"chirp {name} = {f} Hz is outside [0, {nyquist:g}) Hz (Nyquist at dt = {dt} s); "
                f"lower it or raise the sample rate"
            )
    t = np.arange(n) * dt
    total = n * dt
    if sweep == "linear":
        phase = 2 * np.pi * (f_start * t + (f_end - f_start) * t**2 / (2 * total))
    elif sweep == "log":
        if f_start <= 0 or f_end <= 0 or f_start == f_end:
            raise ExcitationError(
                "a log chirp needs f_start > 0, f_end > 0 and f_start != f_end; "
                "change the frequencies or use sweep = 'linear'"
            )
        ratio = f_end / f_start
        phase = 2 * np.pi * f_start * total * (ratio ** (t / total) - 1) / math.log(ratio)
    else:
        raise ExcitationError(f"chirp sweep {sweep!r} is unknown; use 'linear' or 'log'")
    return amplitude * np.sin(phase)
