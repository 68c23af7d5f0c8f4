"""The PRBS is a true m-sequence; the other excitation signals honour their parameters."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import toeplitz

from groundstation.errors import PlanError
from groundstation.plan.excitation import (
    LFSR_TAPS,
    ExcitationError,
    chirp,
    doublet,
    mls_bits,
    prbs,
    prbs_period,
    prbs_persistence_order,
    prbs_shift,
    register_length_for_period,
    step,
)


def _polymulmod(a: int, b: int, poly: int, n: int) -> int:
    result = 0
    while b:
        if b & 1:
            result ^= a
        b >>= 1
        a <<= 1
        if (a >> n) & 1:
            a ^= poly
    return result


def _x_power(e: int, poly: int, n: int) -> int:
    result, base = 1, 2
    while e:
        if e & 1:
            result = _polymulmod(result, base, poly, n)
        base = _polymulmod(base, base, poly, n)
        e >>= 1
    return result


def _prime_factors(m: int) -> set[int]:
    out, d = set(), 2
    while d * d <= m:
        while m % d == 0:
            out.add(d)
            m //= d
        d += 1
    return out | ({m} if m > 1 else set())


@pytest.mark.parametrize("n", sorted(LFSR_TAPS))
def test_every_tap_set_is_primitive(n):
    """x has multiplicative order 2^n - 1 modulo the characteristic polynomial."""
    poly = 1 << n
    for t in LFSR_TAPS[n]:
        poly ^= 1 << (n - t)
    order = (1 << n) - 1
    assert _x_power(order, poly, n) == 1
    for q in _prime_factors(order):
        assert _x_power(order // q, poly, n) != 1, f"n={n}: order divides {order // q}"


@pytest.mark.parametrize("n", range(2, 15))
def test_mls_has_period_balance_and_two_valued_autocorrelation(n):
    period = 2**n - 1
    seed = (0b1011011 % period) or 1
    bits = mls_bits(register_length=n, seed=seed, n_chips=2 * period)
    # Period exactly 2^n - 1: repeats after N chips and after no proper divisor of N.
    assert np.array_equal(bits[:period], bits[period:])
    for d in range(1, period):
        if period % d == 0:
            assert not np.array_equal(bits[:period], np.roll(bits[:period], d))
    s = 2.0 * bits[:period] - 1.0
    assert s.sum() == 1  # one more +1 than -1
    acf = np.real(np.fft.ifft(np.abs(np.fft.fft(s)) ** 2))
    assert acf[0] == pytest.approx(period)
    np.testing.assert_allclose(acf[1:], -1.0, atol=1e-9)


def test_seed_is_initial_register_state_and_seeds_are_shifts():
    n, seed_a, seed_b = 7, 1, 0b1100101
    a = mls_bits(register_length=n, seed=seed_a)
    b = mls_bits(register_length=n, seed=seed_b)
    assert [int(x) for x in b[:n]] == [(seed_b >> i) & 1 for i in range(n)]
    d = prbs_shift(register_length=n, seed_a=seed_a, seed_b=seed_b)
    assert np.array_equal(b, np.roll(a, -d))
    # Shifted m-sequences are uncorrelated over a period except at lag d.
    sa, sb = 2.0 * a - 1, 2.0 * b - 1
    xcf = np.real(np.fft.ifft(np.fft.fft(sb) * np.conj(np.fft.fft(sa))))
    lags = np.arange(a.size)
    np.testing.assert_allclose(xcf[lags != (a.size - d) % a.size], -1.0, atol=1e-9)


def test_prbs_holds_chips_for_clock_period_with_given_amplitude():
    u = prbs(n_samples=100, register_length=5, clock_period=3, amplitude=25.0, seed=9)
    bits = mls_bits(register_length=5, seed=9, n_chips=34)
    assert u.shape == (100,)
    assert set(np.unique(u)) == {-25.0, 25.0}
    np.testing.assert_array_equal(u, np.repeat(np.where(bits == 1, 25.0, -25.0), 3)[:100])
    assert prbs_period(register_length=5, clock_period=3) == 93


@pytest.mark.parametrize(("n", "p"), [(3, 1), (4, 1), (3, 2), (4, 3), (5, 2)])
def test_persistence_order_matches_covariance_rank(n, p):
    """PE of order L: the L x L autocovariance matrix is positive definite; L + 1 is singular."""
    u = prbs(
        n_samples=prbs_period(register_length=n, clock_period=p),
        register_length=n,
        clock_period=p,
        seed=3,
    )
    r = np.real(np.fft.ifft(np.abs(np.fft.fft(u)) ** 2)) / u.size  # periodic autocovariance
    order = prbs_persistence_order(register_length=n, clock_period=p)

    def min_eig(size):
        return np.linalg.eigvalsh(toeplitz(np.resize(r, size)))[0]

    assert min_eig(order) > 1e-8
    assert abs(min_eig(order + 1)) < 1e-8


def test_long_register_generates_requested_chips_quickly():
    bits = mls_bits(register_length=20, seed=12345, n_chips=5000)
    assert bits.shape == (5000,)
    assert abs(int(bits.sum()) - 2500) < 200  # roughly balanced on a window


def test_register_length_for_period():
    assert register_length_for_period(1023) == 10
    with pytest.raises(ExcitationError, match="not 2\\^n - 1"):
        register_length_for_period(1000)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: mls_bits(register_length=1), "register_length 1"),
        (lambda: mls_bits(register_length=25), "register_length 25"),
        (lambda: mls_bits(register_length=4, seed=0), "seed 0"),
        (lambda: mls_bits(register_length=4, seed=16), "from 1 to 15"),
        (lambda: prbs(n_samples=10, register_length=4, clock_period=0), "clock_period 0"),
        (lambda: doublet(n_samples=10, width=4, amplitude=1, start=3), "needs 11 samples"),
        (lambda: step(n_samples=10, amplitude=1, start=10), "step start 10"),
        (lambda: chirp(n_samples=10, dt=0.1, f_start=0.1, f_end=5, amplitude=1), "f_end = 5"),
        (lambda: chirp(n_samples=10, dt=0.1, f_start=0, f_end=2, amplitude=1, sweep="log"), "log"),
    ],
)
def test_bad_parameters_raise_one_line_errors(call, match):
    with pytest.raises(ExcitationError, match=match) as info:
        call()
    assert isinstance(info.value, PlanError) and isinstance(info.value, ValueError)
    assert "\n" not in str(info.value)


def test_doublet_and_step_shapes():
    u = doublet(n_samples=10, width=2, amplitude=3.0, start=1)
    np.testing.assert_array_equal(u, [0, 3, 3, -3, -3, 0, 0, 0, 0, 0])
    np.testing.assert_array_equal(step(n_samples=5, amplitude=-2.0, start=3), [0, 0, 0, -2, -2])


@pytest.mark.parametrize("sweep", ["linear", "log"])
def test_chirp_instantaneous_frequency_runs_from_f_start_to_f_end(sweep):
    dt, n = 0.001, 20000
    u = chirp(n_samples=n, dt=dt, f_start=1.0, f_end=20.0, amplitude=2.0, sweep=sweep)
    assert np.max(np.abs(u)) <= 2.0 and np.max(np.abs(u)) > 1.99
    # Zero crossings per second in the first and last tenths give the local frequency.
    crossings = np.flatnonzero(np.diff(np.signbit(u)))
    early = np.sum(crossings < n // 10) / (2 * n // 10 * dt)
    late = np.sum(crossings >= n - n // 10) / (2 * n // 10 * dt)
    assert 1.0 <= early < (3.0 if sweep == "linear" else 1.5)
    assert (18.0 if sweep == "linear" else 15.0) < late <= 20.5
