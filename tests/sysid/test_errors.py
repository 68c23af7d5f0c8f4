"""Bad input to the identification: one-line ValueErrors that say what to change (item 6)."""

from __future__ import annotations

import numpy as np
import pytest

import sysid
from sysid.data import block_hankel
from sysid.factor import build_products, min_samples
from tests.sysid.systems import open_loop, random_stable_system


@pytest.fixture(scope="module")
def data() -> sysid.IOData:
    system = random_stable_system(n_states=2, n_inputs=2, n_outputs=2,
                                  rng=np.random.default_rng(1))
    return open_loop(system, n_samples=600, rng=np.random.default_rng(2)).data


def _one_line(exc: pytest.ExceptionInfo, *words: str) -> None:
    msg = str(exc.value)
    assert "\n" not in msg, msg
    for w in words:
        assert w in msg, (w, msg)


def test_nan_names_channel_and_sample(data) -> None:
    y = data.y.copy()
    y[123, 1] = np.nan
    with pytest.raises(sysid.DataError) as exc:
        sysid.IOData(u=data.u, y=y, dt=data.dt)
    _one_line(exc, "y channel 1", "sample 123")


def test_too_few_samples_states_the_minimum(data) -> None:
    short = sysid.IOData(u=data.u[:60], y=data.y[:60], dt=data.dt)
    need = min_samples(past=10, future=8, n_channels=4)
    with pytest.raises(sysid.DataError) as exc:
        sysid.iem(short, order=2, past=10, future=8)
    _one_line(exc, "60 samples", f"need at least {need}", "shorter horizons")
    assert isinstance(exc.value, ValueError)
    # the stated minimum is sufficient
    ok = sysid.IOData(u=data.u[:need], y=data.y[:need], dt=data.dt)
    assert build_products(ok, past=10, future=8).n_columns >= 18 * 4


@pytest.mark.parametrize("method", [sysid.iem, sysid.po_moesp])
def test_order_larger_than_available_rank(data, method) -> None:
    with pytest.raises(sysid.OrderError) as exc:
        method(data, order=20, past=10, future=8)
    _one_line(exc, "order=20", "rank available ((future - 1) x 2 outputs = 14",
              "lower the order or use future >= 11")
    # when the past sets the limit, the advice names the past
    with pytest.raises(sysid.OrderError) as exc:
        method(data, order=5, past=1, future=8)
    _one_line(exc, "past x 4 channels = 4", "past >= 2")


def test_order_must_be_positive(data) -> None:
    with pytest.raises(sysid.OrderError) as exc:
        sysid.iem(data, order=0, past=10, future=8)
    _one_line(exc, "order=0", "positive integer")


def test_constant_channel(data) -> None:
    u = data.u.copy()
    u[:, 1] = 1500.0
    with pytest.raises(sysid.DataError) as exc:
        sysid.iem(sysid.IOData(u=u, y=data.y, dt=data.dt, input_names=["m1", "m2"]),
                  order=2, past=10, future=8)
    _one_line(exc, "input channel 1", "'m2'", "constant")


def test_channel_constant_after_linear_detrend(data) -> None:
    """What linear detrending leaves of a constant channel (rounding noise) is still constant."""
    u = data.u.copy()
    u[:, 0] = 3.0
    flat, _ = sysid.detrend_data(sysid.IOData(u=u, y=data.y, dt=data.dt), kind="linear")
    assert 0 < flat.u[:, 0].std() < 1e-12
    for call in (lambda: sysid.iem(flat, order=2, past=10, future=8),
                 lambda: sysid.po_moesp(flat, order=2, past=10, future=8),
                 lambda: sysid.singular_values(flat, past=10, future=8)):
        with pytest.raises(sysid.DataError) as exc:
            call()
        _one_line(exc, "input channel 0", "constant")


def test_channel_constant_within_each_flight(data) -> None:
    """Different constants per flight still make the channel's delayed copies identical."""
    flights = []
    for i, part in enumerate((slice(0, 300), slice(300, 600))):
        u = data.u[part].copy()
        u[:, 1] = 1000.0 * (i + 1)
        flights.append(sysid.IOData(u=u, y=data.y[part], dt=data.dt))
    with pytest.raises(sysid.DataError) as exc:
        sysid.iem(flights, order=2, past=5, future=5)
    _one_line(exc, "input channel 1", "constant in every flight")
    # constant in one flight only is fine: the other flight excites it
    flights[1] = sysid.IOData(u=data.u[300:], y=data.y[300:], dt=data.dt)
    assert sysid.iem(flights, order=2, past=5, future=5).n_states == 2


def test_transposed_arrays_get_a_hint(data) -> None:
    with pytest.raises(sysid.DataError) as exc:
        sysid.iem(sysid.IOData(u=data.u.T, y=data.y.T, dt=data.dt), order=2, past=5, future=5)
    _one_line(exc, "looks transposed")


def test_short_flight_in_a_list_is_logged(data, caplog) -> None:
    short = sysid.IOData(u=data.u[:8], y=data.y[:8], dt=data.dt)
    with caplog.at_level("WARNING", logger="sysid.factor"):
        sysid.iem([data, short], order=2, past=5, future=5)
    assert "flight(s) [1] shorter than past + future = 10 samples" in caplog.text


def test_mismatched_lengths(data) -> None:
    with pytest.raises(sysid.DimensionError) as exc:
        sysid.IOData(u=data.u, y=data.y[:-1], dt=data.dt)
    _one_line(exc, "600 samples", "599", "same length")
    assert isinstance(exc.value, ValueError)


def test_flights_with_different_channels(data) -> None:
    other = sysid.IOData(u=data.u[:, :1], y=data.y, dt=data.dt)
    with pytest.raises(sysid.DimensionError) as exc:
        sysid.iem([data, other], order=2, past=5, future=5)
    _one_line(exc, "data[1]", "same channels")


@pytest.mark.parametrize(("past", "future", "word"), [(0, 5, "past=0"), (5, 1, "future=1"),
                                                      (5.5, 5, "past=5.5")])
def test_bad_horizons(data, past, future, word) -> None:
    with pytest.raises(sysid.HorizonError) as exc:
        sysid.iem(data, order=2, past=past, future=future)
    _one_line(exc, word, "integer horizon")


def test_duplicated_channel_is_rank_deficient(data) -> None:
    u = np.hstack([data.u[:, :1], data.u[:, :1]])
    with pytest.raises(sysid.DataError) as exc:
        sysid.iem(sysid.IOData(u=u, y=data.y, dt=data.dt), order=2, past=5, future=5)
    _one_line(exc, "rank deficient", "drop redundant channels")


@pytest.mark.parametrize(("kwargs", "word"), [({"bk_method": "x"}, "bk_method"),
                                              ({"weighting": "x"}, "weighting")])
def test_unknown_options(data, kwargs, word) -> None:
    with pytest.raises(sysid.ParameterError) as exc:
        sysid.iem(data, order=2, past=5, future=5, **kwargs)
    _one_line(exc, word)
    with pytest.raises(ValueError):
        sysid.singular_values(data, past=5, future=5, method="n4sid")


def test_gram_matches_explicit_hankel(data) -> None:
    """The lag-correlation Gram equals W W^T of the explicit Hankel matrices, summed."""
    a = sysid.IOData(u=data.u[:300], y=data.y[:300], dt=data.dt)
    b = sysid.IOData(u=data.u[300:], y=data.y[300:], dt=data.dt)
    prod = build_products([a, b], past=4, future=3)
    w = np.hstack([block_hankel(prod.scaled_w(d), block_rows=7) for d in (a, b)])
    assert np.allclose(prod.gram, w @ w.T, rtol=1e-12, atol=1e-9)
    assert prod.n_columns == w.shape[1]
