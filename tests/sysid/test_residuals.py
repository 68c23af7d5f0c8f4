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
    (degenerate-data review); at scale 1 the cross-correlation test gives p = 0.29."""
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
