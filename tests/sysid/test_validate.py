"""compare(): fit definition, simulation with estimated x0 (whole / windows), k-step prediction."""

from __future__ import annotations

import numpy as np
import pytest

from sysid.data import IOData
from sysid.errors import DataError, DimensionError, HorizonError
from sysid.model import StateSpaceModel
from sysid.validate import compare, fit_percent, predict
from tests.sysid.systems import closed_loop, pbsid_example1, random_stable_system


def test_fit_percent_matches_definition() -> None:
    rng = np.random.default_rng(0)
    y = rng.normal(size=(500, 3)) + np.array([1.0, -2.0, 5.0])
    dev = y - y.mean(axis=0)
    np.testing.assert_allclose(fit_percent(y, y), 100.0)
    np.testing.assert_allclose(fit_percent(y, np.broadcast_to(y.mean(axis=0), y.shape)), 0.0,
                               atol=1e-12)
    # An error of exactly 10 % / 150 % of the deviation norm per channel.
    np.testing.assert_allclose(fit_percent(y, y + dev * [0.1, 1.5, -0.1]), [90.0, -50.0, 90.0])
    assert fit_percent(y[:, 0], y[:, 0]).shape == (1,)
    const = np.column_stack([y[:, 0], np.full(500, 3.0)])
    fit = fit_percent(const, const + 0.1)
    assert np.isnan(fit[1]) and np.isfinite(fit[0])
    with pytest.raises(DimensionError, match="differ"):
        fit_percent(y, y[:, :2])


def _noise_free(system: StateSpaceModel, *, n: int, x0: np.ndarray, seed: int) -> IOData:
    u = np.random.default_rng(seed).normal(size=(n, system.n_inputs))
    return IOData(u=u, y=system.simulate(u, x0=x0), dt=system.dt)


def test_simulation_of_true_system_recovers_x0_and_fits_100() -> None:
    rng = np.random.default_rng(1)
    system = random_stable_system(n_states=5, n_inputs=2, n_outputs=3, rng=rng)
    x0 = rng.normal(size=5) * 5
    data = _noise_free(system, n=800, x0=x0, seed=2)
    res = compare(system, data)
    np.testing.assert_allclose(res.x0[0][0], x0, atol=1e-8)
    assert np.all(res.fit > 99.9999)
    assert res.mode == "simulation" and res.model_stable and not res.diverged
    # With x0 = 0 the transient is missed: fit visibly lower (x0 matters).
    assert np.min(compare(system, data, x0="zero").fit) < 99.0


def test_windowed_simulation_recovers_state_at_each_window_start() -> None:
    rng = np.random.default_rng(3)
    system = random_stable_system(n_states=4, n_inputs=2, n_outputs=2, rng=rng)
    data = _noise_free(system, n=1030, x0=rng.normal(size=4), seed=4)
    # True state trajectory, to compare with each window's estimated initial state.
    x = np.zeros((data.n_samples, 4))
    x[0] = compare(system, data).x0[0][0]
    for k in range(data.n_samples - 1):
        x[k + 1] = system.A @ x[k] + system.B @ data.u[k]
    res = compare(system, data, window=2.0)  # dt 0.02 s -> 100 samples, 10 windows
    assert res.window == 100 and res.x0[0].shape == (10, 4)  # remainder 30 joins the last
    np.testing.assert_allclose(res.x0[0], x[::100][:10], atol=1e-7)
    assert np.all(res.fit > 99.9999) and res.mode == "windowed simulation"


def _brute_force_prediction(system: StateSpaceModel, data: IOData, *, horizon: int,
                            x0: np.ndarray) -> np.ndarray:
    """y(t|t-k) by explicit loops: Kalman predictor up to t-k+1, then open-loop."""
    a, b, c, d, k = system.A, system.B, system.C, system.D, system.K
    u, y = data.u, data.y
    xh = [x0]
    for j in range(data.n_samples - 1):
        xh.append(a @ xh[j] + b @ u[j] + k @ (y[j] - c @ xh[j] - d @ u[j]))
    out = np.empty_like(y)
    for t in range(data.n_samples):
        start = t - horizon + 1
        z = xh[start] if start >= 0 else x0
        for j in range(max(start, 0), t):
            z = a @ z + b @ u[j]
        out[t] = c @ z + d @ u[t]
    return out


@pytest.mark.parametrize("horizon", [1, 3, 12])
def test_k_step_prediction_matches_explicit_predictor(horizon: int) -> None:
    exp = closed_loop(pbsid_example1(), n_samples=200, rng=np.random.default_rng(5))
    x0 = np.array([0.3, -1.0, 0.5, 2.0])
    got, _ = predict(exp.system, u=exp.data.u, y=exp.data.y, horizon=horizon, x0=x0)
    ref = _brute_force_prediction(exp.system, exp.data, horizon=horizon, x0=x0)
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-10)


def test_prediction_longer_than_record_is_simulation() -> None:
    exp = closed_loop(pbsid_example1(), n_samples=300, rng=np.random.default_rng(6))
    got, _ = predict(exp.system, u=exp.data.u, y=exp.data.y, horizon=10_000, x0="zero")
    np.testing.assert_allclose(got, exp.system.simulate(exp.data.u), rtol=1e-10, atol=1e-10)


def test_one_step_prediction_with_true_k_is_innovation_limited() -> None:
    exp = closed_loop(pbsid_example1(), n_samples=4000, rng=np.random.default_rng(7))
    y = exp.data.y
    innovation_limited = fit_percent(y, y - exp.e)  # the best any predictor can do
    fits = {h: compare(exp.system, exp.data, horizon=h).fit for h in (1, 2, 5, 50)}
    np.testing.assert_allclose(fits[1], innovation_limited, atol=0.1)
    # Less information -> worse prediction, approaching simulation for long horizons.
    assert np.all(fits[1] > fits[2]) and np.all(fits[2] > fits[5]) and np.all(fits[5] > fits[50])
    sim = compare(exp.system, exp.data).fit
    np.testing.assert_allclose(fits[50], sim, atol=1.0)


def _rate_loop(*, seed: int, n: int = 6000) -> tuple[StateSpaceModel, IOData]:
    """Motor command -> angular rate: a near integrator (pole 0.999) behind a motor lag."""
    a = np.array([[0.999, 0.05], [0.0, 0.7]])
    system = StateSpaceModel(A=a, B=[[0.0], [0.3]], C=[[1.0, 0.0]], K=[[0.5], [0.2]], dt=0.01)
    exp = closed_loop(system, n_samples=n, rng=np.random.default_rng(seed), gain=0.05,
                      noise_std=0.1)
    return system, exp.data


def test_integrator_like_system_drifts_in_simulation_but_not_in_windows_or_prediction() -> None:
    system, data = _rate_loop(seed=8)
    sim = compare(system, data).fit[0]
    windowed = compare(system, data, window=0.5).fit[0]
    ahead = compare(system, data, horizon=5).fit[0]
    # The true model: over 60 s the integrated noise dominates pure simulation ...
    assert sim < 20.0
    # ... while windows with their own x0 and 5-step prediction (0.05 s) follow the data.
    assert windowed > 80.0 and ahead > 70.0


def test_multi_experiment_compare_gives_each_its_own_x0_and_fit() -> None:
    rng = np.random.default_rng(9)
    system = random_stable_system(n_states=3, n_inputs=1, n_outputs=2, rng=rng)
    x0s = [rng.normal(size=3) * 3, rng.normal(size=3) * 3]
    flights = [_noise_free(system, n=400, x0=x0, seed=10 + i) for i, x0 in enumerate(x0s)]
    res = compare(system, flights)
    assert res.fits.shape == (2, 2) and len(res.y_model) == 2
    for i in range(2):
        np.testing.assert_allclose(res.x0[i][0], x0s[i], atol=1e-8)
    assert np.all(res.fits > 99.9999)


def test_compare_result_is_the_per_channel_fit() -> None:
    """``compare(...) -> per-channel fit``: the result acts as the (l,) fit array."""
    system = pbsid_example1()
    data = _noise_free(system, n=200, x0=np.ones(4), seed=12)
    res = compare(system, data, horizon=3)
    fit = np.asarray(res)
    assert fit.shape == (2,) and np.array_equal(fit, res.fit)
    assert len(res) == 2 and res[1] == res.fit[1] and list(res) == list(res.fit)
    assert np.array_equal(res >= 99.0, res.fit >= 99.0) and bool(np.all(res > 99.0))
    assert np.array_equal(res - fit, np.zeros(2)) and np.mean(res) == np.mean(res.fit)


def test_compare_rejects_bad_requests() -> None:
    system = pbsid_example1()
    data = _noise_free(system, n=100, x0=np.zeros(4), seed=11)
    with pytest.raises(HorizonError, match="either horizon or window"):
        compare(system, data, horizon=2, window=10.0)
    with pytest.raises(HorizonError, match="too short"):
        compare(system, data, window=1.0)  # dt = 1 s: 1 sample, 2 outputs, 4 states
    with pytest.raises(HorizonError, match="positive"):
        compare(system, data, horizon=0)
    with pytest.raises(HorizonError, match="whole number"):
        compare(system, data, horizon=2.5)
    with pytest.raises(DataError, match=r"dt=2\.0 s but the model has dt=1\.0 s"):
        compare(system, IOData(u=data.u, y=data.y, dt=2.0))
    with pytest.raises(DimensionError, match="x0 has 3 entries"):
        compare(system, data, x0=np.zeros(3))
    with pytest.raises(DimensionError, match="2 inputs/2 outputs"):
        compare(system, IOData(u=data.u[:, :1], y=data.y, dt=1.0))


def test_iem_model_of_rate_loop_validates_like_the_true_model() -> None:
    from sysid.iem import iem

    system, ident = _rate_loop(seed=20)
    _, fresh = _rate_loop(seed=21)
    model = iem(ident, order=2, past=20, future=10)
    for kwargs in ({"horizon": 1}, {"horizon": 5}, {"window": 0.5}):
        got = compare(model, fresh, **kwargs).fit[0]
        truth = compare(system, fresh, **kwargs).fit[0]
        assert got > 80.0 and abs(got - truth) < 1.0, kwargs
    assert compare(model, fresh).fit[0] < 0.0  # whole-record simulation drifts away


def test_modal_simulation_equals_the_sample_loop() -> None:
    """Long runs go through one first-order filter per mode; the result is the recursion's,
    for complex, real, slightly unstable and (falling back to the loop) defective A."""
    from sysid import validate

    rng = np.random.default_rng(7)
    rot = 0.97 * np.array([[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]])
    cases = [np.block([[rot, np.zeros((2, 2))], [np.zeros((2, 2)), np.diag([0.5, 1.001])]]),
             np.array([[0.9, 1.0], [0.0, 0.9]])]  # a Jordan block: the loop
    for a in cases:
        n = a.shape[0]
        bu = rng.standard_normal((3, 500, n))
        x0 = rng.standard_normal((3, n))
        loop = np.empty_like(bu)
        cur = x0.copy()
        for k in range(bu.shape[1]):
            loop[:, k] = cur
            cur = cur @ a.T + bu[:, k]
        got = validate._run_states(A=a, Bu=bu, x0=x0)
        np.testing.assert_allclose(got, loop, rtol=1e-9, atol=1e-9 * np.abs(loop).max())
    assert validate._run_states_modal(A=cases[1], Bu=bu, x0=x0) is None


def test_default_simulation_window_is_2_s_with_a_floor_in_samples():
    """2 s at flight rates; never fewer than 20 samples (DaISy sets have dt = 1 s, where 2 s is
    two samples: x0 fitted exactly, or too few rows to fit it at all); never past the record."""
    from sysid.validate import MIN_WINDOW_SAMPLES, simulation_window

    assert simulation_window(dt=0.02) == pytest.approx(2.0)
    assert simulation_window(dt=0.01, n_samples=150) == pytest.approx(1.5)
    assert simulation_window(dt=1.0) == MIN_WINDOW_SAMPLES == 20
    assert simulation_window(dt=1.0, n_samples=12) == 12
    # an initial state fitted per window needs data: 10 output values per state
    assert simulation_window(dt=1.0, n_states=12, n_outputs=1) == 120
    assert simulation_window(dt=1.0, n_states=12, n_outputs=6) == 20
    assert simulation_window(dt=0.02, n_states=12, n_outputs=1) == pytest.approx(2.4)


def test_min_fit_samples_is_the_floor_of_the_default_window():
    """The one rule for "enough samples to fit an initial state on": what `sysid compare`
    refuses below and what the default window never goes under."""
    from sysid.validate import min_fit_samples, simulation_window

    assert min_fit_samples() == 20
    assert min_fit_samples(n_states=10, n_outputs=4) == 25
    assert min_fit_samples(n_states=12, n_outputs=1) == 120
    for n, outputs in ((1, 1), (10, 4), (12, 1), (40, 6)):
        assert simulation_window(dt=1.0, n_states=n, n_outputs=outputs, samples=1) == (
            min_fit_samples(n_states=n, n_outputs=outputs))


@pytest.mark.parametrize("mode", [{"window": 0.5}, {}, {"horizon": 3}])
def test_fits_do_not_depend_on_the_units_of_a_channel(mode) -> None:
    """The initial state is fitted with every channel weighted as the fit weights it: logging
    one output in units 1000 times smaller (deg/s against a gyro's rad/s) changes no fit. An
    unweighted fit let the large channel decide x0 and the small one drift (demo: -2254 %)."""
    rng = np.random.default_rng(21)
    system = random_stable_system(n_states=6, n_inputs=2, n_outputs=3, rng=rng,
                                  radius=(0.9, 0.99))
    u = rng.normal(size=(1500, 2))
    y = system.simulate(u, x0=rng.normal(size=6) * 3) + 0.3 * rng.normal(size=(1500, 3))
    wrong = system.replace(B=system.B * 1.1)  # a model that is not the system
    units = np.array([1.0, 1e-3, 1e3])
    scaled = wrong.replace(C=wrong.C * units[:, None], D=wrong.D * units[:, None])
    base = compare(wrong, IOData(u=u, y=y, dt=system.dt), **mode)
    again = compare(scaled, IOData(u=u, y=y * units, dt=system.dt), **mode)
    np.testing.assert_allclose(again.fit, base.fit, atol=1e-6)
    assert np.all(base.fit > 50.0), base.fit  # a useful comparison, not three failures alike


@pytest.mark.parametrize("window", [float("nan"), float("inf"), -2.0, "2", True])
def test_compare_refuses_a_window_that_is_not_a_positive_number_of_seconds(window) -> None:
    system = pbsid_example1()
    data = _noise_free(system, n=100, x0=np.zeros(4), seed=11)
    with pytest.raises(HorizonError) as err:
        compare(system, data, window=window)
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith(f"window={window!r}") and "seconds" in msg


def test_windowed_simulation_equals_its_parts_bit_for_bit() -> None:
    """simulate_windows builds each window length's observability matrix once and fits the
    initial states with it: the same numbers as estimate_x0 on the forced responses."""
    from sysid.validate import (
        _run_states,
        channel_weights,
        estimate_x0,
        observability_matrix,
        simulate_windows,
        split_windows,
    )

    rng = np.random.default_rng(7)
    system = random_stable_system(n_states=6, n_inputs=2, n_outputs=3, rng=rng)
    u = rng.normal(size=(1030, 2))
    y = system.simulate(u) + 0.1 * rng.normal(size=(1030, 3))
    y_sim, x0s = simulate_windows(system, u=u, y=y, window=100)
    weights = channel_weights(y)
    slices = split_windows(1030, 100)
    for length in (100, 130):  # the remainder joins the last window
        idx = [i for i, sl in enumerate(slices) if sl.stop - sl.start == length]
        uw = np.stack([u[slices[i]] for i in idx])
        yw = np.stack([y[slices[i]] for i in idx])
        forced = (_run_states(A=system.A, Bu=uw @ system.B.T, x0=np.zeros((len(idx), 6)))
                  @ system.C.T + uw @ system.D.T)
        x0 = estimate_x0(A=system.A, C=system.C, residual=yw - forced, weights=weights)
        np.testing.assert_array_equal(x0s[idx], x0)
        free = np.einsum("kln,wn->wkl", observability_matrix(A=system.A, C=system.C,
                                                             length=length), x0s[idx])
        for j, i in enumerate(idx):
            np.testing.assert_array_equal(y_sim[slices[i]], forced[j] + free[j])
    one = estimate_x0(A=system.A, C=system.C, residual=(y - system.simulate(u))[:100])
    assert one.shape == (6,)


def test_a_model_without_states_compares_in_windows() -> None:
    """A model file of order 0 (A 0 x 0: a static gain, which load reads) made `sysid compare`
    raise ValueError (cannot reshape array of size 0) fitting each window's initial state."""
    rng = np.random.default_rng(0)
    u = rng.standard_normal((400, 2))
    model = StateSpaceModel(A=np.zeros((0, 0)), B=np.zeros((0, 2)), C=np.zeros((1, 0)),
                            D=np.array([[2.0, -1.0]]), K=np.zeros((0, 1)), dt=0.02)
    data = IOData(u=u, y=u @ model.D.T, dt=0.02)
    for window in (1.0, None):
        assert compare(model, data, window=window, warn=False).fit[0] > 99.9
