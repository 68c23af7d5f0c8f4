"""One factorization for a horizon grid equals building every pair on its own data."""

from __future__ import annotations

import numpy as np
import pytest

import sysid
from sysid.errors import DataError, ParameterError
from sysid.grid import build_grid, pair_flights
from sysid.sweep import sweep
from tests.sysid.systems import closed_loop, open_loop, pbsid_example1, random_stable_system

P_MAX, F_MAX = 12, 9


@pytest.fixture(scope="module")
def data() -> sysid.IOData:
    rng = np.random.default_rng(3)
    system = random_stable_system(n_states=4, n_inputs=2, n_outputs=3, rng=rng)
    d = open_loop(system, n_samples=1500, rng=rng, noise_std=0.2).data
    # channels of very different sizes: the per-pair rescaling of the Gram matrix matters
    return sysid.IOData(u=d.u * [1.0, 300.0], y=d.y * [0.01, 1.0, 50.0], dt=d.dt)


def _same(a: sysid.StateSpaceModel, b: sysid.StateSpaceModel) -> None:
    for name in ("A", "B", "C", "D", "K"):
        x, y = getattr(a, name), getattr(b, name)
        np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-9 * np.abs(y).max(), err_msg=name)
    np.testing.assert_allclose(a.provenance["singular_values"],
                               b.provenance["singular_values"], rtol=1e-10)


@pytest.mark.parametrize("feedthrough", [False, True])
def test_iem_pairs_share_one_factor_per_past_and_equal_independent_builds(data, feedthrough):
    grid = build_grid(data, past_max=P_MAX, future_max=F_MAX)
    for past in (3, 7, P_MAX):
        shared = grid.iem_products(past=past, futures=[3, 5, F_MAX], feedthrough=feedthrough)
        for future, products in shared.items():
            data_trimmed = sysid.IOData(
                u=data.u[P_MAX - past: data.n_samples - (F_MAX - future)],
                y=data.y[P_MAX - past: data.n_samples - (F_MAX - future)], dt=data.dt)
            assert data_trimmed.n_samples == pair_flights([data], past=past, future=future,
                                                 past_max=P_MAX, future_max=F_MAX)[0].n_samples
            got = sysid.iem(None, order=4, past=past, future=future, feedthrough=feedthrough,
                            products=products)
            _same(got, sysid.iem(data_trimmed, order=4, past=past, future=future,
                                 feedthrough=feedthrough))


def test_po_moesp_pairs_equal_independent_builds(data):
    grid = build_grid(data, past_max=P_MAX, future_max=F_MAX)
    for past, future in ((3, 4), (P_MAX, F_MAX), (6, 8)):
        own = list(grid.flights_for(past=past, future=future))
        got = sysid.po_moesp(None, order=4, past=past, future=future,
                             products=grid.products(past=past, future=future))
        _same(got, sysid.po_moesp(own, order=4, past=past, future=future))


def test_sweep_rows_equal_independent_builds_closed_loop_two_flights():
    rng = np.random.default_rng(0)
    system = pbsid_example1()
    flights = [closed_loop(system, n_samples=n, rng=rng).data for n in (900, 700)]
    val = closed_loop(system, n_samples=600, rng=rng).data
    result = sweep(flights, pasts=[4, 8], futures=[3, 6], orders=[2, 4], validation=val,
                   horizon=1, keep_models=True)
    assert len(result.rows) == 8
    for row in result.rows:
        own = pair_flights(flights, past=row.past, future=row.future, past_max=8, future_max=6)
        model = sysid.iem(list(own), order=row.order, past=row.past, future=row.future)
        _same(row.model, model)
        np.testing.assert_allclose(row.fit, sysid.compare(model, val, horizon=1).fit,
                                   rtol=1e-9)


def test_grid_refuses_what_the_data_cannot_hold(data):
    with pytest.raises(DataError, match="too few for the largest pair"):
        build_grid(data, past_max=300, future_max=100)
    grid = build_grid(data, past_max=P_MAX, future_max=F_MAX)
    with pytest.raises(DataError, match="outside the grid"):
        grid.products(past=P_MAX + 1, future=2)
    with pytest.raises(sysid.HorizonError, match="products were built for past=3"):
        sysid.iem(None, order=2, past=4, future=3, products=grid.products(past=3, future=3))
    with pytest.raises(ParameterError, match="either as an options object or as keywords"):
        sweep(data, pasts=[3], futures=[3], orders=[2], options=sysid.methods.IEMOptions(),
              feedthrough=True)


def test_orders_of_a_pair_reuse_its_factor_and_svd(data):
    """Every order of a pair is realised from one factorization and one SVD: the second order
    reads what the first stored in the pair's products (tampered here to prove it)."""
    grid = build_grid(data, past_max=P_MAX, future_max=F_MAX)
    pair = grid.iem_products(past=8, futures=[6], feedthrough=False)[6]
    first = sysid.iem(None, order=2, past=8, future=6, products=pair)
    key = ("iem-svd", "data", False)
    u, s = pair.cache[key]
    np.testing.assert_allclose(s, first.provenance["singular_values"])
    pair.cache[key] = (u, 2.0 * s)
    second = sysid.iem(None, order=3, past=8, future=6, products=pair)
    np.testing.assert_allclose(second.provenance["singular_values"], 2.0 * s)
    moesp = grid.products(past=8, future=6)
    sysid.po_moesp(None, order=2, past=8, future=6, products=moesp)
    assert set(moesp.cache) == {("moesp", "auto"), "moesp-svd"}
    l4 = moesp.cache[("moesp", "auto")][0]
    sysid.po_moesp(None, order=3, past=8, future=6, products=moesp)
    assert moesp.cache[("moesp", "auto")][0] is l4
