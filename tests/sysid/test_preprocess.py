"""Preprocessing: ZOH resampling of irregular streams, trimming, detrending (thesis 4.3.1)."""

from __future__ import annotations

import numpy as np
import pytest

from sysid.data import IOData
from sysid.errors import DataError, DimensionError
from sysid.preprocess import (
    Stream,
    detrend,
    detrend_data,
    iodata_from_streams,
    resample_streams,
    trim,
    uniform_grid,
    zoh_resample,
)


def _irregular_times(rng: np.random.Generator, *, n: int, mean_dt: float, t0: float) -> np.ndarray:
    """Strictly increasing times with jitter of +-40 % of the mean period."""
    steps = mean_dt * rng.uniform(0.6, 1.4, size=n)
    return t0 + np.concatenate([[0.0], np.cumsum(steps[:-1])])


def test_zoh_reproduces_held_values_exactly() -> None:
    rng = np.random.default_rng(0)
    t = _irregular_times(rng, n=400, mean_dt=0.013, t0=0.37)
    v = rng.normal(size=t.size)
    grid = np.arange(t[0], t[-1], 0.02)
    out = zoh_resample(t=t, values=v, grid=grid)
    # Truth by brute force: the last sample whose time is <= the grid instant.
    truth = np.array([v[np.flatnonzero(t <= g)[-1]] for g in grid])
    np.testing.assert_array_equal(out, truth)


def test_zoh_sample_on_grid_instant_is_taken_despite_rounding() -> None:
    # Samples meant to lie on the grid but carrying float noise just above it.
    grid = 0.1 * np.arange(10)
    t = grid + 1e-12
    t[0] = 0.0
    v = np.arange(10.0)
    np.testing.assert_array_equal(zoh_resample(t=t, values=v, grid=grid), v)


def test_zoh_repeated_instant_takes_last_sample() -> None:
    t = np.array([0.0, 1.0, 1.0, 2.0])
    v = np.array([10.0, 11.0, 12.0, 13.0])
    out = zoh_resample(t=t, values=v, grid=np.array([0.5, 1.0, 1.5, 2.5]))
    np.testing.assert_array_equal(out, [10.0, 12.0, 12.0, 13.0])


def test_zoh_grid_before_first_sample_is_an_error() -> None:
    with pytest.raises(DataError, match="precedes the first sample"):
        zoh_resample(t=np.array([1.0, 2.0]), values=np.ones(2), grid=np.array([0.5, 1.5]))


def test_resample_streams_aligns_on_common_window() -> None:
    rng = np.random.default_rng(1)
    a_t = _irregular_times(rng, n=300, mean_dt=0.02, t0=0.05)
    b_t = _irregular_times(rng, n=500, mean_dt=0.011, t0=0.21)
    a = Stream("a", a_t, np.sin(a_t), unit="V")
    b = Stream("b", b_t, np.cos(b_t), unit="A")
    grid, values = resample_streams(streams=[a, b], dt=0.02)
    assert grid[0] == pytest.approx(b_t[0])  # latest first sample
    assert grid[-1] <= min(a_t[-1], b_t[-1]) + 1e-9
    assert values.shape == (grid.size, 2)
    np.testing.assert_allclose(np.diff(grid), 0.02, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(values[:, 0], zoh_resample(t=a_t, values=a.values, grid=grid))
    np.testing.assert_array_equal(values[:, 1], zoh_resample(t=b_t, values=b.values, grid=grid))


def test_resample_warns_about_log_gaps(caplog: pytest.LogCaptureFixture) -> None:
    t = np.concatenate([np.arange(0, 1, 0.01), np.arange(2, 3, 0.01)])  # 1 s gap
    s = Stream("gyro", t, np.ones_like(t))
    with caplog.at_level("WARNING", logger="sysid.preprocess"):
        resample_streams(streams=[s], dt=0.02, max_hold=0.05)
    assert "gyro" in caplog.text and "log gaps" in caplog.text
    caplog.clear()  # from a file: the line names it (8 such lines of a batch named none)
    with caplog.at_level("WARNING", logger="sysid.preprocess"):
        u = Stream("u", np.arange(0, 3, 0.01), np.arange(300.0))
        data = iodata_from_streams(streams=[s, u], inputs=["u"],
                                   outputs=["gyro"], dt=0.02, max_hold=0.05, source="f.h5")
    assert caplog.messages == ["f.h5: stream 'gyro': 48 grid instants hold a sample older "
                               "than 0.050 s (log gaps)"]
    assert data.source == "f.h5"


def test_uniform_grid_rejects_start_before_data_and_bad_dt() -> None:
    s = Stream("x", np.array([1.0, 2.0, 3.0]), np.zeros(3))
    with pytest.raises(DataError, match="start"):
        uniform_grid(streams=[s], dt=0.1, start=0.5)
    with pytest.raises(DataError, match="dt"):
        uniform_grid(streams=[s], dt=0.0)
    grid = uniform_grid(streams=[s], dt=0.5, start=1.2, stop=2.2)
    np.testing.assert_allclose(grid, [1.2, 1.7, 2.2])


def test_stream_validation_names_stream_and_sample() -> None:
    with pytest.raises(DataError, match=r"'m1'.*backwards at sample 2"):
        Stream("m1", np.array([0.0, 1.0, 0.5]), np.zeros(3))
    with pytest.raises(DataError, match=r"'m1'.*sample 1"):
        Stream("m1", np.array([0.0, 1.0, 2.0]), np.array([0.0, np.nan, 1.0]))
    with pytest.raises(DimensionError, match="'m1'"):
        Stream("m1", np.zeros(3), np.zeros(4))


def test_iodata_from_streams_carries_names_units_and_window() -> None:
    rng = np.random.default_rng(2)
    streams = []
    for name, unit in (("m1", "PWM"), ("m2", "PWM"), ("gx", "deg/s")):
        t = _irregular_times(rng, n=600, mean_dt=0.01, t0=rng.uniform(0, 0.05))
        streams.append(Stream(name, t, rng.normal(size=t.size), unit=unit))
    data = iodata_from_streams(
        streams=streams, inputs=["m2", "m1"], outputs=["gx"], dt=0.02, start=1.0, stop=4.0
    )
    assert data.input_names == ("m2", "m1") and data.output_names == ("gx",)
    assert data.input_units == ("PWM", "PWM") and data.output_units == ("deg/s",)
    assert data.n_samples == 151 and data.dt == 0.02
    grid = 1.0 + 0.02 * np.arange(151)
    by = {s.name: s for s in streams}
    np.testing.assert_array_equal(data.u[:, 0], zoh_resample(t=by["m2"].t, values=by["m2"].values,
                                                             grid=grid))
    with pytest.raises(DataError, match=r"no stream named \['acc'\]"):
        iodata_from_streams(streams=streams, inputs=["m1"], outputs=["acc"], dt=0.02)


def test_trim_keeps_inclusive_window() -> None:
    data = IOData(u=np.arange(100.0), y=np.arange(100.0) ** 2, dt=0.1, source="f1")
    cut = trim(data, start=2.0, stop=3.0)
    np.testing.assert_array_equal(cut.u[:, 0], np.arange(20.0, 31.0))
    np.testing.assert_array_equal(cut.y[:, 0], np.arange(20.0, 31.0) ** 2)
    assert cut.source == "f1" and cut.dt == 0.1
    with pytest.raises(DataError, match="holds no sample"):
        trim(data, start=20.0, stop=30.0)


@pytest.mark.parametrize("kind", ["mean", "linear"])
def test_detrend_removes_known_trend_and_restores_exactly(kind: str) -> None:
    time = 5.0 + 0.01 * np.arange(1000)
    offset, slope = np.array([3.0, -7.0]), np.array([0.5, 2.0])
    if kind == "mean":
        slope = np.zeros(2)
    signal = np.sin(2 * np.pi * 1.3 * time)[:, None] * np.array([1.0, 0.2])
    signal = signal - signal.mean(axis=0)
    if kind == "linear":  # make the zero-trend part orthogonal to the line
        design = np.column_stack([np.ones_like(time), time - time[0]])
        signal = signal - design @ np.linalg.lstsq(design, signal, rcond=None)[0]
    x = offset + (time - time[0])[:, None] * slope + signal
    x_d, trend = detrend(x, time=time, kind=kind)
    np.testing.assert_allclose(trend.offset, offset, atol=1e-9)
    np.testing.assert_allclose(trend.slope, slope, atol=1e-9)
    np.testing.assert_allclose(x_d, signal, atol=1e-9)
    np.testing.assert_allclose(trend.restore(x_d, time=time), x, atol=1e-12)
    # The trend can be re-applied on a different time vector (e.g. a model's output).
    later = time[-1] + 1.0
    np.testing.assert_allclose(trend.evaluate(np.array([later]))[0],
                               offset + (later - time[0]) * slope)


def test_detrend_data_and_unknown_kind() -> None:
    t = 0.02 * np.arange(200)
    data = IOData(u=np.column_stack([2 + t, np.sin(t)]), y=10 - 3 * t + np.cos(5 * t), dt=0.02)
    flat, trends = detrend_data(data, kind="linear")
    np.testing.assert_allclose(trends.u.slope[0], 1.0, atol=1e-9)
    assert abs(flat.y.mean()) < 1e-9
    np.testing.assert_allclose(trends.y.restore(flat.y, time=data.time), data.y, atol=1e-12)
    with pytest.raises(DataError, match="'quadratic'"):
        detrend(data.u, time=data.time, kind="quadratic")  # type: ignore[arg-type]
