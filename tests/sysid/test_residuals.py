"""Residual analysis and information criteria on a known closed-loop system (issue 10 item 5)."""

from __future__ import annotations

import numpy as np
import pytest

import sysid
from tests.sysid.systems import pbsid_example1_closed_loop


@pytest.fixture(scope="module")
def experiment():
    return pbsid_example1_closed_loop(rng=np.random.default_rng(1))


def test_true_order_residuals_are_white_and_independent(experiment):
    model = sysid.iem(experiment.data, order=4, past=20, future=10)
    res = sysid.residuals(model, experiment.data)
    assert res.white.all() and res.independent.all(), res.summary()
    assert res.autocorr.shape == (26, 2) and res.crosscorr.shape == (51, 2, 2)
    assert np.allclose(res.autocorr[0], 1.0)
    assert res.auto_bound == pytest.approx(2.5758 / np.sqrt(4000), rel=1e-3)
    assert (res.auto_outside <= 0.1).all()


def test_under_ordered_model_is_not_white(experiment):
    model = sysid.iem(experiment.data, order=2, past=20, future=10)
    res = sysid.residuals(model, experiment.data)
    assert not res.white.any(), res.summary()
    assert "NO" in res.summary()


def test_wrong_b_is_flagged_by_the_cross_correlation(experiment):
    model = sysid.iem(experiment.data, order=4, past=20, future=10)
    bad = model.replace(B=model.B * np.array([1.0, 0.8]))
    res = sysid.residuals(bad, experiment.data)
    assert not res.independent.any(), res.summary()


def test_flights_are_pooled_not_joined(experiment):
    d = experiment.data
    half = [sysid.IOData(u=d.u[:2000], y=d.y[:2000], dt=d.dt),
            sysid.IOData(u=d.u[2000:], y=d.y[2000:], dt=d.dt)]
    model = sysid.iem(experiment.data, order=4, past=20, future=10)
    res = sysid.residuals(model, half, max_lag=10)
    assert [r.shape for r in res.residuals] == [(2000, 2), (2000, 2)]
    assert res.n_samples == 4000 and res.autocorr.shape == (11, 2)


def test_bad_arguments_are_one_line_errors(experiment):
    model = sysid.iem(experiment.data, order=4, past=20, future=10)
    with pytest.raises(sysid.ParameterError, match="max_lag"):
        sysid.residuals(model, experiment.data, max_lag=0)
    with pytest.raises(sysid.ParameterError, match="confidence"):
        sysid.residuals(model, experiment.data, confidence=1.5)


def test_information_criteria_pick_the_true_order(experiment):
    ic = sysid.information_criteria(experiment.data, orders=range(1, 9), past=20, future=10)
    assert ic.chosen == {"aic": 4, "aicc": 4, "bic": 4}
    # n (2 l + m) + n per flight, no D for IEM's default
    assert list(ic.n_params[:2]) == [1 * 6 + 1, 2 * 6 + 2]
    assert np.all(ic.bic - ic.aic == pytest.approx(ic.n_params * (np.log(4000) - 2)))


@pytest.mark.parametrize("scale", [1e80, 1e-100])
def test_the_verdicts_do_not_depend_on_the_data_scale(scale):
    """At 1e80 the sums of products overflowed (cross-correlation 0, "independent", p = 1) and
    at 1e-100 underflowed ("not independent", p = 0), at magnitudes the data checks accept
    (degenerate-data review); at scale 1 the cross-correlation test gives p = 0.33."""
    from scipy.signal import lfilter

    u = np.sign(np.random.default_rng(0).standard_normal(2000))
    y = lfilter([0, 1, 0.3], [1, -1.35, 0.486], u)
    y = y + 0.05 * np.random.default_rng(1).standard_normal(2000)
    one = sysid.IOData(u=u, y=y, dt=0.01)
    scaled = sysid.IOData(u=u * scale, y=y * scale, dt=0.01)
    ref = sysid.residuals(sysid.iem(one, order=2, past=10, future=10), one)
    with np.errstate(over="raise", divide="raise", invalid="raise"):  # no inf, no 0/0
        res = sysid.residuals(sysid.iem(scaled, order=2, past=10, future=10), scaled)
    np.testing.assert_allclose(res.cross_p, ref.cross_p, rtol=1e-6)
    np.testing.assert_allclose(res.p_value, ref.p_value, rtol=1e-6)
    assert list(res.independent) == list(ref.independent) == [True]


def _oe_experiment(rng: np.random.Generator, *, noise_ma: list[float], n_samples: int = 1000):
    """The true output-error model (K = 0) of a coloured input (pole 0.95) and its data with
    moving-average noise ``noise_ma`` (independent of the input): its residuals are the noise."""
    from scipy.signal import lfilter

    model = sysid.StateSpaceModel(A=np.array([[0.8, 0.2], [-0.2, 0.8]]), B=np.array([[1.0], [0.5]]),
                                  C=np.array([[1.0, 0.0]]), D=np.zeros((1, 1)), K=np.zeros((2, 1)),
                                  dt=0.01)
    u = lfilter([1.0], [1.0, -0.95], rng.standard_normal(n_samples))[:, None]
    y = model.simulate(u) + lfilter(noise_ma, [1.0], rng.standard_normal(n_samples))[:, None]
    return model, sysid.IOData(u=u, y=y, dt=0.01)


def test_independence_statistic_uses_the_covariance_of_the_lags():
    """Ljung's test of past inputs (System Identification, 2nd ed., section 16.6) generalised to
    a coloured residual, from the definitions: ``Q = N r^T P^-1 r`` over lags 1..M, with
    ``P_kj = sum_{|t|<=M} rho_e(t) rho_u(t + j - k)`` the covariance of the lags of ``r``. Before,
    ``N sum r(k)^2 / P_kk`` took the lags as independent."""
    from scipy import stats

    model, data = _oe_experiment(np.random.default_rng(3), noise_ma=[1.0, 0.8, 0.5])
    big_m = 10
    res = sysid.residuals(model, data, max_lag=big_m)
    e = res.residuals[0][:, 0] - res.residuals[0][:, 0].mean()
    u = data.u[:, 0] - data.u[:, 0].mean()
    n = e.size

    def corr(a, b, k):  # sum_t a(t) b(t-k) / sqrt(sum a^2 sum b^2)
        s = sum(a[t] * b[t - k] for t in range(max(k, 0), min(n, n + k)))
        return s / np.sqrt(np.dot(a, a) * np.dot(b, b))

    rho_e = {k: corr(e, e, k) for k in range(-big_m, big_m + 1)}
    rho_u = {k: corr(u, u, k) for k in range(-2 * big_m, 2 * big_m + 1)}
    r = np.array([corr(e, u, k) for k in range(1, big_m + 1)])
    p_mat = np.array([[sum(rho_e[t] * rho_u[t + j - k] for t in range(-big_m, big_m + 1))
                       for j in range(1, big_m + 1)] for k in range(1, big_m + 1)])
    q = n * r @ np.linalg.solve(p_mat, r)
    np.testing.assert_allclose(res.crosscorr[big_m + 1:, 0, 0], r, rtol=1e-9)
    np.testing.assert_allclose(res.cross_q[0, 0], q, rtol=1e-8)
    np.testing.assert_allclose(res.cross_p[0, 0], stats.chi2.sf(q, big_m), rtol=1e-6)
    assert res.cross_bound[0, 0] == pytest.approx(2.5758 * np.sqrt(p_mat[0, 0] / n), rel=1e-4)


@pytest.mark.parametrize("noise_ma", [[1.0], [1.0, 0.8, 0.5]], ids=["white", "coloured"])
def test_independence_false_alarms_stay_near_the_confidence(noise_ma):
    """The true model on a coloured input, noise independent of it: "not independent" at 99 %
    should come about 1 % of the time. Taking the lags as independent said so for 19 % (white
    noise) and 20 % (coloured) of these 150 records each; now 2 % and 2 %."""
    rng = np.random.default_rng(5)
    alarms = [not sysid.residuals(*_oe_experiment(rng, noise_ma=noise_ma),
                                  max_lag=20).independent[0] for _ in range(150)]
    assert np.mean(alarms) <= 0.05
