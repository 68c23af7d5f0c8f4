"""Exactly noise-free data give the exact system (sysid/factor.py, iem.py, moesp.py, parsim.py).

With n states the joint Hankel matrix has rank (p + f) m + n, not (p + f)(m + l): the outputs
are functions of the inputs and the state. That is the deterministic case every subspace text
treats, not an error: the dependent rows get no direction of their own and the regressions are
solved exactly. Channels dependent at lag 0 (duplicates, an input copying an output, constants)
and inputs that are not persistently exciting are still refused, in one line naming them."""

from __future__ import annotations

import numpy as np
import pytest

import sysid
from sysid.data import IOData, block_hankel
from sysid.errors import DataError
from sysid.factor import build_products, solve_right, triangular_factor
from sysid.iem import iem_order

from .systems import closed_loop, open_loop, pole_error, random_stable_system

SYSTEM = random_stable_system(n_states=4, n_inputs=2, n_outputs=2,
                              rng=np.random.default_rng(71), dt=0.01)


def _split(data: IOData, cut: int) -> tuple[IOData, IOData]:
    return (IOData(u=data.u[:cut], y=data.y[:cut], dt=data.dt),
            IOData(u=data.u[cut:], y=data.y[cut:], dt=data.dt))


def _check_exact(model: sysid.StateSpaceModel, val: IOData) -> None:
    assert pole_error(SYSTEM.poles(), model.poles()) < 1e-8
    fit = sysid.compare(model, val, warn=False).fit  # from x0 = least squares
    assert np.all(fit > 99.9999), fit


@pytest.mark.parametrize("method", ["iem", "po_moesp", "parsim_k"])
@pytest.mark.parametrize("feedthrough", [False, True])
def test_noise_free_open_loop_gives_the_exact_system(method, feedthrough):
    ex = open_loop(SYSTEM, n_samples=2000, rng=np.random.default_rng(1), noise_std=0.0)
    ident, val = _split(ex.data, 1400)
    model = getattr(sysid, method)(ident, order=4, past=10, future=10, feedthrough=feedthrough)
    _check_exact(model, val)


@pytest.mark.parametrize("focus", ["prediction", "simulation"])
def test_noise_free_closed_loop_gives_the_exact_system_with_iem(focus):
    """u = r - F y without delay: the loop is exact too (r excites; nothing is dependent at
    lag 0)."""
    ex = closed_loop(SYSTEM, n_samples=2000, rng=np.random.default_rng(2), gain=0.3,
                     noise_std=0.0)
    ident, val = _split(ex.data, 1400)
    _check_exact(sysid.iem(ident, order=4, past=8, future=8, focus=focus), val)


def test_singular_values_show_the_order_exactly_and_a_higher_order_is_refused():
    ex = open_loop(SYSTEM, n_samples=1500, rng=np.random.default_rng(3), noise_std=0.0)
    for method in ("iem", "po-moesp"):
        sv = sysid.singular_values(ex.data, past=10, future=10, method=method)
        assert sv[3] > 1e-3 * sv[0] and sv[4] < 1e-10 * sv[0], (method, sv[:6])
    with pytest.raises(sysid.OrderError, match="numerical rank of the data"):
        sysid.iem(ex.data, order=6, past=10, future=10)


def test_sweep_over_a_grid_of_noise_free_data_is_exact():
    """The grid's shared IEM factor (rescaled per pair) keeps the dependent rows' zeros."""
    ex = open_loop(SYSTEM, n_samples=1500, rng=np.random.default_rng(4), noise_std=0.0)
    ident, val = _split(ex.data, 1000)
    result = sysid.sweep(ident, pasts=[5, 8], futures=[4, 7], orders=[4], validation=val)
    assert all(row.error is None and row.mean_fit > 99.999 for row in result.rows), \
        result.table()


def test_parsim_k_takes_the_deterministic_predictor():
    """Noise-free data leave K undetermined; y_0 depends on Z_p and u_0, so it gets no
    coefficient and the predictor is the system itself (A_K = A, K = 0) rather than an
    arbitrary share of the minimum-norm solution."""
    ex = open_loop(SYSTEM, n_samples=1500, rng=np.random.default_rng(5), noise_std=0.0)
    model = sysid.parsim_k(ex.data, order=4, past=3, future=4, feedthrough=False)
    assert np.abs(model.K).max() < 1e-6
    assert pole_error(SYSTEM.poles(), np.linalg.eigvals(model.A - model.K @ model.C)) < 1e-8


def test_dependent_rows_get_a_zero_column_and_the_factor_still_spans_the_data():
    ex = open_loop(SYSTEM, n_samples=600, rng=np.random.default_rng(6), noise_std=0.0)
    products = build_products(ex.data, past=6, future=6)
    order = iem_order(products, feedthrough=False)
    low = triangular_factor(products, order)
    zero = np.diag(low) == 0.0
    assert zero.sum() == 12 * 2 - 4  # (p + f) l rows of outputs, n of them independent
    assert np.all(low[:, zero] == 0.0) and np.allclose(low, np.tril(low))
    w = block_hankel(products.scaled_w(ex.data), block_rows=12)[order]
    np.testing.assert_allclose(low @ low.T, w @ w.T, rtol=1e-9, atol=1e-9 * w.shape[1])
    # the basic solution of a regression is exact: the last dependent row from those before it
    k = int(np.flatnonzero(zero)[-1])
    theta = solve_right(low[:k, :k], low[k:k + 1, :k])
    np.testing.assert_allclose(theta @ w[:k], w[k:k + 1], atol=1e-8)


@pytest.mark.parametrize(("make", "words"), [
    (lambda u, y: (np.column_stack([u[:, 0], u[:, 0]]), y),
     ["input channel 1 ('u1')", "input channel 0 ('u0')", "drop redundant channels"]),
    (lambda u, y: (np.column_stack([u[:, 0], y[:, 1]]), y),
     ["output channel 1 ('y1')", "input channel 1 ('u1')", "drop redundant channels"]),
    (lambda u, y: (u, np.column_stack([y[:, 0], -3.0 * y[:, 0]])),
     ["output channel 1 ('y1')", "output channel 0 ('y0')", "rank deficient"]),
    (lambda u, y: (np.column_stack([u[:, 0], np.full(len(u), 2.0)]), y),
     ["input channel 1 ('u1')", "constant"]),
])
def test_genuinely_redundant_channels_are_still_refused_by_name(make, words):
    ex = open_loop(SYSTEM, n_samples=800, rng=np.random.default_rng(7), noise_std=0.0)
    u, y = make(ex.data.u, ex.data.y)
    data = IOData(u=u, y=y, dt=0.01)
    for call in (lambda: sysid.iem(data, order=4, past=8, future=8),
                 lambda: sysid.po_moesp(data, order=4, past=8, future=8),
                 lambda: sysid.parsim_k(data, order=4, past=8, future=8)):
        with pytest.raises(DataError) as err:
            call()
        msg = str(err.value)
        assert "\n" not in msg and all(w in msg for w in words), msg


def test_an_input_that_is_a_delayed_copy_is_not_persistently_exciting():
    rng = np.random.default_rng(8)
    r = rng.standard_normal(801)
    u = np.column_stack([r[1:], r[:-1]])  # u1(k) = u0(k - 1)
    data = IOData(u=u, y=SYSTEM.simulate(u), dt=0.01)
    for method in (sysid.iem, sysid.po_moesp, sysid.parsim_k):
        with pytest.raises(DataError, match="not persistently exciting") as err:
            method(data, order=4, past=8, future=8)
        assert "\n" not in str(err.value)
