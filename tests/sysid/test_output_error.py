"""sysid.output_error: B, D and the initial states by simulation error, given A and C."""

from __future__ import annotations

import logging

import numpy as np
import pytest

import sysid
from sysid import output_error
from sysid.output_error import _responses, output_error_bd


def test_output_error_recovers_b_d_x0_exactly_on_noise_free_data():
    rng = np.random.default_rng(0)
    a = np.diag([0.9, 0.5, -0.3, 0.7])
    a[0, 1] = 0.3
    b, c, d = rng.normal(size=(4, 2)), rng.normal(size=(3, 4)), rng.normal(size=(3, 2))
    x0 = rng.normal(size=4)
    u = rng.normal(size=(400, 2))
    y = sysid.StateSpaceModel(A=a, B=b, C=c, D=d).simulate(u, x0=x0)
    b_est, d_est, x0s = output_error_bd(a=a, c=c, flights=[(u, y)], feedthrough=True)
    np.testing.assert_allclose(b_est, b, atol=1e-9)
    np.testing.assert_allclose(d_est, d, atol=1e-9)
    np.testing.assert_allclose(x0s[0], x0, atol=1e-9)
    # the modal (filter) route and the plain recursion agree
    [(_, r1, f1)] = list(_responses(a, c, u))
    modal, output_error._modal = output_error._modal, lambda a, c: None
    try:
        [(_, r2, f2)] = list(_responses(a, c, u))
    finally:
        output_error._modal = modal
    np.testing.assert_allclose(r1, r2, atol=1e-10)
    np.testing.assert_allclose(f1, f2, atol=1e-10)


@pytest.mark.parametrize("modal", [True, False])
def test_blocks_of_samples_give_the_same_fit_and_residuals(monkeypatch, modal):
    """The regression is formed block by block (memory O(CHUNK), not O(N)): the filters'
    states and the powers of A carry over, so any block length gives the same estimate."""
    rng = np.random.default_rng(4)
    a = np.array([[0.9, 0.3, 0.0], [0.0, 0.9, 0.0], [0.0, 0.0, -0.5]]) if not modal else \
        np.diag([0.95, 0.6, -0.4])
    b, c = rng.normal(size=(3, 2)), rng.normal(size=(2, 3))
    flights = []
    for n in (1000, 333):
        u = rng.normal(size=(n, 2))
        y = sysid.StateSpaceModel(A=a, B=b, C=c).simulate(u, x0=rng.normal(size=3))
        flights.append((u, y + 0.1 * rng.normal(size=y.shape)))
    whole = output_error_bd(a=a, c=c, flights=flights, feedthrough=True, residuals=True)
    monkeypatch.setattr(output_error, "CHUNK", 37)
    blocks = output_error_bd(a=a, c=c, flights=flights, feedthrough=True, residuals=True)
    for x, y in zip(whole[:2], blocks[:2], strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-10)
    for x, y in zip([*whole[2], *whole[3]], [*blocks[2], *blocks[3]], strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-10)
    assert [e.shape for e in blocks[3]] == [(1000, 2), (333, 2)]


def test_output_error_handles_a_defective_a_by_recursion():
    a = np.array([[0.8, 1.0], [0.0, 0.8]])  # Jordan block: not diagonalisable
    b, c = np.array([[0.0], [1.0]]), np.array([[1.0, 0.0]])
    u = np.random.default_rng(1).normal(size=(300, 1))
    y = sysid.StateSpaceModel(A=a, B=b, C=c).simulate(u)
    b_est, d_est, _ = output_error_bd(a=a, c=c, flights=[(u, y)], feedthrough=False)
    np.testing.assert_allclose(b_est, b, atol=1e-8)
    assert not d_est.any()


def test_a_defective_a_whose_responses_overflow_is_fitted_without_numpy_warnings():
    """The recursion's overflow is the growth the fit leaves out, as on the modal path: no
    RuntimeWarning reaches the caller (no-knobs identification leaked 39 of them)."""
    import warnings

    a = np.array([[1.3, 1.0], [0.0, 1.3]])  # a Jordan block: 1.3^k overflows near k = 2700
    c = np.array([[1.0, 0.0]])
    u = np.random.default_rng(1).normal(size=(3000, 1))
    y = np.random.default_rng(2).normal(size=(3000, 1))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        b_est, _, _ = output_error_bd(a=a, c=c, flights=[(u, y)], feedthrough=False)
    assert np.isfinite(b_est).all()


def _system(seed: int = 2) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = np.array([[0.8, 0.2], [-0.2, 0.8]])  # poles 0.8 ± 0.2j
    return a, rng.normal(size=(2, 1)), rng.normal(size=(2, 2)), rng.normal(size=(2, 1))


def test_flights_share_b_d_and_each_has_its_own_x0():
    a, b, c, d = _system()
    model = sysid.StateSpaceModel(A=a, B=b, C=c, D=d)
    rng = np.random.default_rng(3)
    x0s = [np.array([2.0, -1.0]), np.array([-3.0, 0.5]), np.zeros(2)]
    flights = []
    for x0, n in zip(x0s, (150, 80, 200), strict=True):  # flights of different lengths
        u = rng.normal(size=(n, 1))
        flights.append((u, model.simulate(u, x0=x0)))
    b_est, d_est, x0_est, errs = output_error_bd(a=a, c=c, flights=flights, feedthrough=True,
                                                residuals=True)
    np.testing.assert_allclose(b_est, b, atol=1e-9)
    np.testing.assert_allclose(d_est, d, atol=1e-9)
    for est, true in zip(x0_est, x0s, strict=True):
        np.testing.assert_allclose(est, true, atol=1e-9)
    assert [e.shape for e in errs] == [(150, 2), (80, 2), (200, 2)]
    assert max(abs(e).max() for e in errs) < 1e-9


def test_without_x0_the_start_transient_is_left_in_the_residuals():
    """``estimate_x0=False`` imposes x0 = 0: a flight that starts away from rest then fits
    worse than with x0 estimated, and its x0 is reported as zeros."""
    a, b, c, d = _system()
    u = np.random.default_rng(4).normal(size=(200, 1))
    y = sysid.StateSpaceModel(A=a, B=b, C=c, D=d).simulate(u, x0=np.array([5.0, 5.0]))
    *_, with_x0, err_x0 = output_error_bd(a=a, c=c, flights=[(u, y)], feedthrough=True,
                                          residuals=True)
    *_, without, err_zero = output_error_bd(a=a, c=c, flights=[(u, y)], feedthrough=True,
                                            estimate_x0=False, residuals=True)
    np.testing.assert_allclose(with_x0[0], [5.0, 5.0], atol=1e-9)
    assert not without[0].any()
    assert np.sum(err_zero[0] ** 2) > 1e3 * max(np.sum(err_x0[0] ** 2), 1e-20)


def _unstable(radius: float, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                              np.ndarray]:
    """A (unstable pole ``radius`` and 0.5), C, B, u, y of a noise-free flight from x0."""
    a = np.array([[radius, 0.0], [0.0, 0.5]])
    b, c = np.array([[1.0], [1.0]]), np.array([[1.0, 1.0]])
    u = np.random.default_rng(5).normal(size=(n, 1))
    return a, c, b, u, sysid.StateSpaceModel(A=a, B=b, C=c).simulate(u, x0=np.array([1.0, -1.0]))


def test_a_slightly_unstable_a_still_fits_exactly():
    a, c, b, u, y = _unstable(1.05, 200)  # grows 1.05^200 = 1.7e4: every sample kept
    b_est, _, x0s, errs = output_error_bd(a=a, c=c, flights=[(u, y)], feedthrough=False,
                                          residuals=True)
    assert len(errs[0]) == 200
    np.testing.assert_allclose(b_est, b, atol=1e-6)
    np.testing.assert_allclose(x0s[0], [1.0, -1.0], atol=1e-6)


def test_samples_whose_responses_explode_are_left_out_and_logged(caplog):
    a, c, _, u, y = _unstable(1.5, 200)
    with caplog.at_level(logging.INFO, logger="sysid.output_error"):
        *_, errs = output_error_bd(a=a, c=c, flights=[(u, y)], feedthrough=False,
                                   residuals=True)
    assert len(errs[0]) == 69  # 1.5^k passes 1e12 at k = 69: the fit is over the start
    assert any("131 samples left out" in r.getMessage() for r in caplog.records)


@pytest.mark.xfail(strict=True, reason="normal equations lose the start of the flight when the "
                   "kept responses reach 1e12: B = [0.25, 0.89] for [1, 1] at |z| = 1.1")
def test_a_clearly_unstable_a_fits_the_start_exactly():
    a, c, b, u, y = _unstable(1.1, 400)
    b_est, _, x0s = output_error_bd(a=a, c=c, flights=[(u, y)], feedthrough=False)
    np.testing.assert_allclose(b_est, b, atol=1e-6)
    np.testing.assert_allclose(x0s[0], [1.0, -1.0], atol=1e-6)


@pytest.mark.parametrize("start", [0, 200])  # 1.24 ** 3200: 1e296, still finite
def test_mode_powers_are_numpys_complex_powers(start):
    """The impulse-filter powers (5-6 times faster than ``lam ** k``, which took most of a
    one-step fit's time) equal numpy's, stable, on the circle, unstable, at 0 and complex."""
    from sysid.output_error import mode_powers

    lam = np.array([0.0, 1.0, -0.5, 0.999 * np.exp(0.3j), 1.2 + 0.3j, 0.3 - 0.9j])
    direct = lam[None, :] ** np.arange(start, start + 3000)[:, None]
    got = mode_powers(lam, 3000, start=start)
    np.testing.assert_allclose(got, direct, rtol=1e-12, atol=1e-300)
    only = mode_powers(lam, 50, start=start, modes=[1, 3])
    assert not only[:, [0, 2, 4, 5]].any()
    np.testing.assert_allclose(only[:, [1, 3]], direct[:50, [1, 3]], rtol=1e-12)


def test_mode_powers_stop_at_the_floor_before_the_subnormal_numbers():
    """A stable mode's powers are 0 once below ``POWER_FLOOR`` (the impulse filter went on
    into a limit cycle of subnormal numbers, a hundred times slower per sample); the powers
    before are the filter's own, to the bit, also for a block starting at ``start``."""
    import scipy.signal

    from sysid.output_error import POWER_FLOOR, mode_powers

    lam = np.array([0.9, 0.95 * np.exp(0.3j), 0.5 - 0.5j, 0.999, 1.01])
    impulse = np.zeros(20_000)
    impulse[0] = 1.0
    for start in (0, 37, 5000):
        got = mode_powers(lam, impulse.size, start=start)
        for i, li in enumerate(lam):
            full = scipy.signal.lfilter([1.0], [1.0, -li], impulse) * (li ** start if start else 1)
            kept = got[:, i] != 0  # a leading run; the floor, to the recursion's rounding
            assert kept.all() or not kept[np.argmin(kept):].any()
            np.testing.assert_array_equal(got[kept, i], full[kept])
            assert (np.abs(full[~kept]) < 1.0001 * POWER_FLOOR).all()
            assert (np.abs(full[kept]) > 0.9999 * POWER_FLOOR).all()
        assert np.count_nonzero(got[:, 0]) < 7000  # 0.9 ** 6600 = 1e-302
