"""An identified model's ``noise_cov`` is the covariance of its own one-step prediction errors
on the identification data (:mod:`sysid.innovation_cov`), for every method and focus.

The errors are computed here independently: a plain Kalman-predictor loop
``x(t+1) = (A - K C) x + (B - K D) u + K y`` run over the samples, with the initial state
fitted by least squares on the errors, each channel weighted by one over its spread (the
convention of :func:`sysid.validate.predict`). Before, IEM and PO-MOESP returned the covariance
of the subspace step's innovation estimate: 3.3-3.5x the model's own on DaISy cstr, 0.64-0.70x
for PO-MOESP and IEM's simulation focus in closed loop.
"""

from __future__ import annotations

import numpy as np
import pytest

import sysid
from sysid.innovation_cov import OWN, own_noise_cov, without_own_noise_cov
from sysid.live import LiveIdentifier
from tests.sysid.daisy import DAISY, load
from tests.sysid.systems import PBSID_CLOSED_LOOP_NOISE_STD, pbsid_example1_closed_loop


def _own_errors(model: sysid.StateSpaceModel, data: sysid.IOData) -> np.ndarray:
    """``(N, l)`` one-step errors of ``model`` on ``data`` by a loop over the samples; column 0
    of the state block is the response to the data from x0 = 0, columns 1..n the free
    responses to each unit initial state, so x0 is one weighted least-squares fit."""
    a_k = model.A - model.K @ model.C
    b_k = model.B - model.K @ model.D
    n, ell = model.n_states, model.n_outputs
    x = np.hstack([np.zeros((n, 1)), np.eye(n)])
    err0 = np.empty((data.n_samples, ell))
    free = np.empty((data.n_samples, ell, n))
    for t in range(data.n_samples):
        y_hat = model.C @ x
        err0[t] = data.y[t] - y_hat[:, 0] - model.D @ data.u[t]
        free[t] = y_hat[:, 1:]
        x = a_k @ x
        x[:, 0] += b_k @ data.u[t] + model.K @ data.y[t]
    w = 1.0 / data.y.std(axis=0)
    x0 = np.linalg.lstsq((free * w[:, None]).reshape(-1, n), (err0 * w).ravel(), rcond=None)[0]
    return err0 - free @ x0


def _own_cov(model: sysid.StateSpaceModel, flights: list[sysid.IOData]) -> np.ndarray:
    err = np.vstack([_own_errors(model, d) for d in flights])
    return err.T @ err / err.shape[0]


@pytest.fixture(scope="module")
def pbsid() -> sysid.IOData:
    return pbsid_example1_closed_loop(rng=np.random.default_rng(0), n_samples=4000).data


@pytest.mark.parametrize(("method", "options"), [
    (sysid.iem, {}),
    (sysid.iem, {"focus": "simulation"}),  # before: 0.70x
    (sysid.po_moesp, {}),  # before: 0.64-0.70x
    (sysid.parsim_k, {}),
    (sysid.iem, {"focus": "simulation", "pem": True}),  # output error, K = 0
])
def test_closed_loop_noise_cov_is_the_models_own_one_step_error_covariance(pbsid, method,
                                                                           options):
    model = method(pbsid, order=4, past=20, future=20, **options)
    np.testing.assert_allclose(model.noise_cov, _own_cov(model, [pbsid]), rtol=1e-7,
                               atol=1e-10)
    assert model.provenance["noise_cov_source"] == OWN
    assert np.shape(model.provenance["noise_cov_method"]) == (2, 2)


def test_with_enough_data_it_is_the_true_innovation_covariance(pbsid):
    """The true innovations are N(0, 0.49 I): over N samples a variance estimate has standard
    deviation 0.49 sqrt(2/N) (0.011), a covariance 0.49 / sqrt(N); four of them are allowed
    (measured: 0.480, 0.489 and 0.004)."""
    model = sysid.iem(pbsid, order=4, past=20, future=20)
    np.testing.assert_allclose(model.noise_cov, _own_cov(model, [pbsid]), rtol=1e-7)
    var = PBSID_CLOSED_LOOP_NOISE_STD ** 2
    n = pbsid.n_samples
    sd = var * np.array([[np.sqrt(2), 1], [1, np.sqrt(2)]]) / np.sqrt(n)
    assert np.all(np.abs(model.noise_cov - var * np.eye(2)) < 4 * sd), model.noise_cov


@pytest.mark.skipif(not (DAISY / "cstr.dat").is_file(), reason="DaISy sets not in ../shared")
@pytest.mark.parametrize("method", [sysid.iem, sysid.po_moesp])
def test_daisy_cstr_noise_cov_is_the_models_own(method):
    """cstr at order 4: the subspace step's estimate was 3.3-3.5x (IEM) and 1.9-2.0x
    (PO-MOESP) the model's own one-step error covariance."""
    ident, _ = load("cstr")
    model = method(ident, order=4, past=20, future=20, feedthrough=True)
    np.testing.assert_allclose(model.noise_cov, _own_cov(model, [ident]), rtol=1e-7,
                               atol=1e-12 * np.abs(model.noise_cov).max())


def test_output_error_model_carries_its_simulation_error_covariance(pbsid):
    """K = 0 (PO-MOESP's thesis variant; it had no noise_cov): the one-step predictor is the
    simulation, so noise_cov is the covariance of the simulation errors from a fitted x0."""
    model = sysid.po_moesp(pbsid, order=4, past=20, future=20, variant="thesis")
    assert not model.K.any() and model.provenance["noise_cov_method"] is None
    np.testing.assert_allclose(model.noise_cov, _own_cov(model, [pbsid]), rtol=1e-7)


def test_several_flights_each_from_its_own_initial_state(pbsid):
    halves = [sysid.IOData(u=pbsid.u[s], y=pbsid.y[s], dt=pbsid.dt)
              for s in (slice(0, 1800), slice(1800, None))]
    model = sysid.iem(halves, order=4, past=15, future=15)
    np.testing.assert_allclose(model.noise_cov, _own_cov(model, halves), rtol=1e-7)


def test_live_model_carries_its_own_noise_cov(pbsid):
    """Live identification's model: its noise_cov is that of its one-step errors on the
    samples so far (means removed, as the live products have them)."""
    data = sysid.IOData(u=pbsid.u[:1500], y=pbsid.y[:1500], dt=pbsid.dt)
    live = LiveIdentifier(n_inputs=2, n_outputs=2, order=4, past=10, future=5, dt=data.dt)
    live.append(u=data.u, y=data.y)
    model = live.update().model
    centred = sysid.detrend_data(data, kind="mean")[0]
    np.testing.assert_allclose(model.noise_cov, _own_cov(model, [centred]), rtol=1e-7)


def test_unstable_predictor_keeps_the_methods_estimate(pbsid):
    """Its own predictor diverges: the method's estimate stays, and the provenance says so."""
    model = sysid.iem(pbsid, order=4, past=20, future=20)
    bad = model.replace(K=model.K * 8.0, noise_cov=np.diag([2.0, 3.0]))
    assert not bad.predictor_is_stable
    kept = own_noise_cov(bad, flights=[pbsid])
    np.testing.assert_array_equal(kept.noise_cov, np.diag([2.0, 3.0]))
    assert "unstable" in kept.provenance["noise_cov_source"]
    # a method that gave no estimate (PO-MOESP's thesis variant with an unstable A): not
    # called "the method's estimate"
    none = own_noise_cov(bad.replace(noise_cov=None), flights=[pbsid])
    assert none.noise_cov is None
    assert none.provenance["noise_cov_source"] == ("none (the method gave none): the predictor "
                                                   "A - K C is unstable")


def test_a_sweeps_dropped_models_skip_it(pbsid):
    with without_own_noise_cov():
        model = sysid.iem(pbsid, order=4, past=20, future=20)
    assert "not computed" in model.provenance["noise_cov_source"]
    np.testing.assert_array_equal(model.noise_cov, model.provenance["noise_cov_method"])
