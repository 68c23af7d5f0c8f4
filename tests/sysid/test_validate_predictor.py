"""Unstable predictors are flagged; stable_predictor() gives the minimum-phase Kalman gain."""

from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy.linalg import block_diag

from sysid.kalman import stable_predictor
from sysid.model import StateSpaceModel
from sysid.validate import compare, fit_percent
from tests.sysid.systems import closed_loop, random_stable_system

# SISO noise model H(z) = 1 + C (zI - A)^-1 K with A = 0.9, C = 1: zero at A - K.
# K = 0.5 puts the zero at 0.4 (stable predictor). Its mirror image 1/0.4 = 2.5 (K = -1.6) with
# innovation variance scaled by 0.4^2 has exactly the same output spectrum: the same noise seen
# through a non-minimum-phase factor, whose predictor A - KC = 2.5 is unstable.
A_S, K_GOOD, K_BAD, SHRINK = 0.9, 0.5, -1.6, 0.4**2


def _siso(k: float, *, var: float = 1.0) -> StateSpaceModel:
    return StateSpaceModel(A=[[A_S]], B=[[1.0]], C=[[1.0]], K=[[k]], dt=0.01,
                           noise_cov=[[var]])


def test_mirror_factor_is_flagged_and_stabilised_to_the_true_gain(
    caplog: pytest.LogCaptureFixture,
) -> None:
    true = _siso(K_GOOD)
    bad = _siso(K_BAD, var=SHRINK)
    exp = closed_loop(true, n_samples=3000, rng=np.random.default_rng(0), gain=0.2)
    assert not bad.predictor_is_stable
    with caplog.at_level(logging.WARNING, logger="sysid.validate"):
        res = compare(bad, exp.data, horizon=1)
    assert not res.predictor_stable and "unstable" in caplog.text
    assert "stable_predictor" in res.summary()
    assert res.diverged or np.all(res.fit < 0)  # (2.5)^k blows the predictor up
    fixed = stable_predictor(bad)
    np.testing.assert_allclose(fixed.K, [[K_GOOD]], atol=1e-9)
    np.testing.assert_allclose(fixed.noise_cov, [[1.0]], atol=1e-9)  # SHRINK / 0.4^2
    np.testing.assert_array_equal(fixed.A, bad.A)  # dynamics untouched
    assert fixed.predictor_is_stable
    ok = compare(fixed, exp.data, horizon=1)
    np.testing.assert_allclose(ok.fit, fit_percent(exp.data.y, exp.data.y - exp.e), atol=0.1)


def test_stable_predictor_leaves_a_stable_predictor_alone() -> None:
    model = _siso(K_GOOD)
    assert stable_predictor(model) is model


def _noise_spectrum(model: StateSpaceModel, omega: float) -> np.ndarray:
    z = np.exp(1j * omega)
    h = np.eye(model.n_outputs) + model.C @ np.linalg.solve(
        z * np.eye(model.n_states) - model.A, model.K)
    return h @ model.noise_cov @ h.conj().T


def test_mimo_stabilised_predictor_keeps_the_noise_spectrum() -> None:
    rng = np.random.default_rng(1)
    base = random_stable_system(n_states=4, n_inputs=2, n_outputs=2, rng=rng)
    k_bad = 3.0 * rng.normal(size=(4, 2))
    bad = base.replace(K=k_bad, noise_cov=np.array([[1.0, 0.3], [0.3, 0.5]]))
    assert not bad.predictor_is_stable
    fixed = stable_predictor(bad)
    assert fixed.predictor_is_stable
    for omega in (0.05, 0.7, 2.0, 3.1):
        np.testing.assert_allclose(_noise_spectrum(fixed, omega), _noise_spectrum(bad, omega),
                                   rtol=1e-8, atol=1e-10)


def test_two_channel_mirror_recovers_both_true_gains_and_predicts_well() -> None:
    true = StateSpaceModel(A=np.diag([0.9, 0.8]), B=np.eye(2), C=np.eye(2),
                           K=np.diag([0.5, 0.3]), dt=0.01, noise_cov=np.eye(2))
    # Channel 2: zero 0.5 mirrored to 2.0 -> K = 0.8 - 2.0, variance x 0.25.
    bad = true.replace(K=block_diag([[K_BAD]], [[-1.2]]), noise_cov=np.diag([SHRINK, 0.25]))
    exp = closed_loop(true, n_samples=3000, rng=np.random.default_rng(2), gain=0.2)
    fixed = stable_predictor(bad, data=exp.data)
    np.testing.assert_allclose(fixed.K, true.K, atol=1e-9)
    # Covariance estimated from the new predictor's one-step errors: the true innovations'.
    np.testing.assert_allclose(fixed.noise_cov, np.cov(exp.e, rowvar=False), atol=0.01)
    limited = fit_percent(exp.data.y, exp.data.y - exp.e)
    np.testing.assert_allclose(compare(fixed, exp.data, horizon=1).fit, limited, atol=0.1)
