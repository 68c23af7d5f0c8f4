"""Focus (prediction / simulation) and stability modes through the methods (issue 10).

The modules on their own: test_finish.py, test_output_error.py, test_stability.py."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.signal

import sysid
from sysid import IOData
from sysid.stability import MARGINAL_RADIUS

from .systems import (
    closed_loop,
    pbsid_example1,
    pbsid_example1_closed_loop,
    random_stable_system,
)


def _colored_open_loop(*, seed: int, n: int = 3000, noise: float = 0.05, n_true: int = 10,
                       ) -> tuple[sysid.StateSpaceModel, IOData, IOData]:
    """A 2x2 system of ``n_true`` states driven by a low-passed input (colored, not white, like
    most real experiments' inputs), output noise ``noise`` times the output's spread;
    identification and validation sets."""
    rng = np.random.default_rng(seed)
    system = random_stable_system(n_states=n_true, n_inputs=2, n_outputs=2, rng=rng,
                                  feedthrough=True, dt=1.0, radius=(0.7, 0.97))
    sets = []
    for _ in range(2):
        u = scipy.signal.lfilter([1.0], [1.0, -0.97], rng.standard_normal((n, 2)), axis=0)
        y0 = system.simulate(u)
        sets.append(IOData(u=u, y=y0 + noise * y0.std(axis=0) * rng.standard_normal((n, 2)),
                           dt=1.0))
    return system, sets[0], sets[1]


def _sim_fit(model: sysid.StateSpaceModel, data: IOData) -> float:
    return float(np.mean(np.asarray(sysid.compare(model, data))))


def test_po_moesp_simulates_on_colored_inputs_where_eq_3_15_does_not():
    """An order-4 model of a 10-state system (undermodelled, as every real system is) from a
    colored input: output-error B, D beat the thesis' eq. 3.15 on held-out data, with the
    same A, C. Measured gaps 2.5, 18.2 and 3.7 points on seeds 0-2."""
    gaps = []
    for seed in range(3):
        _, ident, val = _colored_open_loop(seed=seed)
        kw = {"order": 4, "past": 20, "future": 20}
        standard = sysid.po_moesp(ident, **kw)
        thesis = sysid.po_moesp(ident, variant="thesis", **kw)
        np.testing.assert_allclose(np.sort_complex(standard.poles()),
                                   np.sort_complex(thesis.poles()), atol=1e-8)
        fit_std, fit_thesis = _sim_fit(standard, val), _sim_fit(thesis, val)
        assert fit_std > 85.0, fit_std
        assert fit_std > fit_thesis + 1.0, (seed, fit_std, fit_thesis)
        gaps.append(fit_std - fit_thesis)
        assert standard.provenance["focus"] == "simulation"
        assert len(standard.provenance["x0"]) == 1
    assert np.mean(gaps) > 5.0, gaps


def test_simulation_focus_is_at_least_as_good_in_simulation_for_open_loop_data():
    _, ident, val = _colored_open_loop(seed=3, noise=0.2, n_true=4)
    kw = {"order": 4, "past": 20, "future": 20, "feedthrough": True}
    sim = sysid.iem(ident, focus="simulation", **kw)
    pred = sysid.iem(ident, focus="prediction", **kw)
    assert _sim_fit(sim, ident) >= _sim_fit(pred, ident) - 1e-6  # it minimises exactly this
    assert _sim_fit(sim, val) > 75.0  # noise is 20 % of the output's spread


def test_prediction_focus_keeps_the_closed_loop_predictor_consistent():
    """In closed loop, output error is biased by the feedback (docs/sysid.md, "Focus"): on
    PBSID Example 1 the one-step predictor of the prediction focus is better on held-out data,
    and its B is closer to the truth."""
    rng = np.random.default_rng(5)
    ident = pbsid_example1_closed_loop(rng=rng).data
    val = pbsid_example1_closed_loop(rng=rng).data
    kw = {"order": 4, "past": 10, "future": 10}
    pred = sysid.iem(ident, focus="prediction", **kw)
    sim = sysid.iem(ident, focus="simulation", **kw)
    one_pred = np.mean(np.asarray(sysid.compare(pred, val, horizon=1)))
    one_sim = np.mean(np.asarray(sysid.compare(sim, val, horizon=1)))
    assert one_pred > one_sim, (one_pred, one_sim)
    # transfer-function error over frequency (basis-free): |G_est - G_true| / |G_true|
    g0 = pbsid_example1()
    w = np.linspace(0.05, 3.0, 40)

    def freq(m: sysid.StateSpaceModel) -> np.ndarray:
        return np.stack([m.C @ np.linalg.solve(np.exp(1j * x) * np.eye(m.n_states) - m.A, m.B)
                         + m.D for x in w])

    err_pred = np.linalg.norm(freq(pred) - freq(g0)) / np.linalg.norm(freq(g0))
    err_sim = np.linalg.norm(freq(sim) - freq(g0)) / np.linalg.norm(freq(g0))
    assert err_pred < err_sim, (err_pred, err_sim)


@pytest.mark.filterwarnings("error::RuntimeWarning")  # no numpy warning leaks to the user
def test_an_unstable_plant_identified_in_closed_loop_is_kept_by_default_and_reflected_on_request():
    a = np.array([[1.25, 0.0], [0.0, 0.6]])
    plant = sysid.StateSpaceModel(A=a, B=[[1.0], [0.5]], C=[[1.0, 1.0]], K=[[0.5], [0.2]],
                                  dt=1.0)
    # u = r - 0.8 y stabilises it (closed-loop poles inside)
    exp = closed_loop(plant, n_samples=4000, rng=np.random.default_rng(2), gain=0.8,
                      noise_std=0.1)
    kw = {"order": 2, "past": 10, "future": 10}
    auto = sysid.iem(exp.data, **kw)
    assert max(abs(auto.poles())) == pytest.approx(1.25, abs=0.02)
    enforced = sysid.iem(exp.data, stability="enforce", **kw)
    assert max(abs(enforced.poles())) < 1.0
    report = enforced.provenance["stability"]
    assert report["moved"] and report["measure"] == "1-step prediction"
    assert report["cost_points"] > 0  # moving a real instability costs fit, and it is said
    free = sysid.iem(exp.data, stability="free", **kw)
    np.testing.assert_allclose(np.sort(abs(free.poles())), np.sort(abs(auto.poles())))


def test_focus_and_stability_are_checked():
    _, ident, _ = _colored_open_loop(seed=0, n=500)
    with pytest.raises(sysid.ParameterError, match="focus"):
        sysid.iem(ident, order=2, past=5, future=5, focus="sim")
    with pytest.raises(sysid.ParameterError, match="stability"):
        sysid.po_moesp(ident, order=2, past=5, future=5, stability="strict")
    with pytest.raises(sysid.ParameterError, match="thesis"):
        sysid.iem(ident, order=2, past=5, future=5, variant="thesis", focus="simulation")


def test_to_control_accepts_session_channel_names():
    control = pytest.importorskip("control")
    m = sysid.StateSpaceModel(A=0.5 * np.eye(2), B=np.ones((2, 4)), C=np.ones((6, 2)), dt=0.02,
                              input_names=[f"motor.m{i}" for i in range(1, 5)],
                              output_names=[f"acc.{a}" for a in "xyz"]
                              + [f"gyro.{a}" for a in "xyz"])
    sys_c = m.to_control()
    assert isinstance(sys_c, control.StateSpace) and sys_c.dt == 0.02
    assert sys_c.input_labels[0] == "motor_m1" and sys_c.output_labels[3] == "gyro_x"
    np.testing.assert_allclose(sys_c.A, m.A)


def test_stability_cost_in_simulation_focus_is_measured_over_windows():
    """A pole just outside the circle (an integrator's estimate) moved by ``stability="auto"``:
    its cost in simulation focus is measured over short windows, a figure of a few points, not
    the whole-record simulation of the unstable free model (which made it 1e6 points)."""
    rng = np.random.default_rng(3)
    a = np.array([[1.004, 0.0], [0.0, 0.8]])
    system = sysid.StateSpaceModel(A=a, B=np.array([[0.1], [1.0]]), C=np.array([[1.0, 1.0]]),
                                   D=np.zeros((1, 1)), dt=0.02)
    u = np.sign(rng.standard_normal((3000, 1)))
    y = system.simulate(u)
    data = IOData(u=u, y=y + 0.01 * y.std() * rng.standard_normal(y.shape), dt=0.02)
    model = sysid.iem(data, order=2, past=10, future=10, focus="simulation")
    report = model.provenance["stability"]
    assert report["moved"] and max(abs(model.poles())) <= MARGINAL_RADIUS + 1e-9
    assert report["measure"] == "simulation (2 s windows)"
    assert report["cost_points"] is not None and abs(report["cost_points"]) < 50.0


def _pi_loop(seed: int, *, n: int = 5000, burn: int = 1000) -> tuple[IOData, float]:
    """A rate loop: plant poles 0.999 (the integrator's estimate) and 0.8 (a motor lag), a PI
    controller on a PRBS reference (clock 10), process noise and colored output noise entering
    before the feedback; the data and the plant's DC gain."""
    a = np.array([[0.999, 0.05], [0.0, 0.8]])
    b, c = np.array([0.0, 0.2]), np.array([1.0, 0.0])
    rng = np.random.default_rng(seed)
    total = n + burn
    r = np.repeat(rng.choice([-1.0, 1.0], size=total // 10 + 1), 10)[:total]
    v = scipy.signal.lfilter([1.0], [1.0, -0.9], rng.standard_normal(total) * 0.1) * np.sqrt(0.19)
    w = rng.standard_normal((total, 2)) * 0.02
    x, integral, u, y = np.zeros(2), 0.0, np.empty(total), np.empty(total)
    for k in range(total):
        y[k] = c @ x + v[k]
        err = r[k] - y[k]
        u[k] = 1.5 * err + 0.05 * integral
        integral += err
        x = a @ x + b * u[k] + w[k]
    dc = float(c @ np.linalg.solve(np.eye(2) - a, b))
    return IOData(u=u[burn:, None], y=y[burn:, None], dt=0.002), dc


@pytest.mark.parametrize("seed", [7, 8])
def test_the_default_model_of_a_near_integrating_closed_loop_keeps_the_plants_dc_gain(seed):
    """Two estimated poles just outside the circle moved onto 0.999 together became a Jordan
    block, and the default model's DC gain was 2.7 (seed 7) or 0.2 (seed 8) times the plant's
    (robustness review, 2026-11-28): now within 25 % on both."""
    data, dc = _pi_loop(seed)
    model = sysid.identify(data).model
    gain = float((model.C @ np.linalg.solve(np.eye(model.n_states) - model.A, model.B)
                  + model.D)[0, 0])
    assert 0.8 < gain / dc < 1.25, (gain / dc, np.abs(model.poles()))
