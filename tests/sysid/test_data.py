"""sysid.data: IOData (checked, read-only, labelled), several flights, block Hankel views and
the excitation check (its refusals through the methods: test_errors.py)."""

from __future__ import annotations

import re

import numpy as np
import pytest

import sysid
from sysid.data import as_flights, block_hankel, check_excited, hankel_columns
from sysid.errors import DataError, DimensionError


def test_iodata_promotes_1d_and_is_read_only() -> None:
    d = sysid.IOData(u=np.arange(5.0), y=np.ones((5, 2)) * [1, 2], dt=0.02)
    assert d.u.shape == (5, 1) and (d.n_samples, d.n_inputs, d.n_outputs) == (5, 1, 2)
    assert np.allclose(d.time, [0, 0.02, 0.04, 0.06, 0.08])
    assert d.output_names == ("y0", "y1") and d.input_units == ("",)
    with pytest.raises(ValueError):
        d.u[0, 0] = 3.0


@pytest.mark.parametrize(
    ("kwargs", "words"),
    [
        ({"u": np.zeros((5, 1)), "y": np.zeros((4, 1))}, ["5 samples", "4", "same length"]),
        ({"u": np.zeros((5, 1)), "y": np.array([[0], [1], [np.nan], [0], [0]])},
         ["y channel 0", "sample 2", "nan"]),
        ({"u": np.array([[0, 0], [0, np.inf]]), "y": np.zeros((2, 1))},
         ["u channel 1", "sample 1", "inf"]),
        ({"u": np.zeros((2, 1, 1)), "y": np.zeros((2, 1))}, ["u has 3 dimensions"]),
        ({"u": np.zeros((2, 1)), "y": np.zeros((2, 1)), "output_names": ["a", "b"]},
         ["output_names", "give exactly 1"]),
    ],
)
def test_iodata_bad_input_is_one_line_value_error(kwargs: dict, words: list[str]) -> None:
    with pytest.raises(ValueError) as info:
        sysid.IOData(dt=0.1, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg
    for w in words:
        assert w in msg


def test_block_hankel_layout() -> None:
    x = np.arange(12.0).reshape(6, 2)
    h = block_hankel(x, block_rows=3, start=1)
    assert h.shape == (6, 3)
    for i in range(3):
        for j in range(3):
            assert np.array_equal(h[2 * i:2 * i + 2, j], x[1 + i + j])


def test_iodata_copies_its_inputs_and_builds_the_joint_signal():
    u, y = np.arange(4.0).reshape(4, 1), np.ones((4, 2))
    d = sysid.IOData(u=u, y=y, dt=0.5, input_names=["m1"], output_units=["g", "deg/s"])
    u[0, 0] = 99.0  # the caller's array is not the data's
    assert d.u[0, 0] == 0.0 and d.dt == 0.5 and isinstance(d.dt, float)
    np.testing.assert_array_equal(d.w, np.hstack([d.u, d.y]))
    assert d.input_names == ("m1",) and d.output_units == ("g", "deg/s")
    assert d.output_names == ("y0", "y1") and d.input_units == ("",)


@pytest.mark.parametrize("dt", [0.0, -0.02, float("nan"), float("inf")])
def test_iodata_refuses_a_sample_period_that_is_not_positive(dt):
    with pytest.raises(DataError, match="sample period in seconds"):
        sysid.IOData(u=np.zeros(3), y=np.zeros(3), dt=dt)


def _flight(n: int = 50, *, m: int = 1, ell: int = 2, dt: float = 0.02, seed: int = 0):
    rng = np.random.default_rng(seed)
    return sysid.IOData(u=rng.normal(size=(n, m)), y=rng.normal(size=(n, ell)), dt=dt)


def test_as_flights_takes_one_or_several_consistent_flights():
    a, b = _flight(seed=1), _flight(80, seed=2)
    assert as_flights(a) == (a,)
    assert as_flights([a, b]) == (a, b)
    assert as_flights([a, _flight(dt=0.02 * (1 + 1e-12))])  # same rate up to rounding


@pytest.mark.parametrize(("flights", "error", "words"), [
    ([], DataError, "no data given"),
    ([np.zeros((5, 2))], DataError, "data[0] is a ndarray; wrap arrays in sysid.IOData"),
    ([_flight(), _flight(m=2)], DimensionError, "data[1] has 2 inputs/2 outputs but data[0] has "
                                                "1/2"),
    ([_flight(), _flight(dt=0.01)], DataError, "data[1] has dt=0.01 s but data[0] has dt=0.02 s"),
])
def test_as_flights_names_the_flight_that_does_not_fit(flights, error, words):
    with pytest.raises(error) as info:
        as_flights(flights)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_hankel_columns_never_negative_and_match_block_hankel():
    x = np.arange(20.0).reshape(10, 2)
    for rows in (1, 4, 10):
        assert block_hankel(x, block_rows=rows).shape == (2 * rows, hankel_columns(10,
                                                                                   block_rows=rows))
    assert hankel_columns(3, block_rows=5) == 0


def test_check_excited_returns_the_spread_over_all_flights():
    rng = np.random.default_rng(3)
    a = sysid.IOData(u=rng.normal(0, 2.0, (4000, 1)), y=rng.normal(0, 0.5, (4000, 1)), dt=0.1)
    b = sysid.IOData(u=rng.normal(0, 2.0, (4000, 1)), y=rng.normal(0, 0.5, (4000, 1)), dt=0.1)
    u_std, y_std = check_excited([a, b])
    assert u_std.shape == (1,) and y_std.shape == (1,)
    assert u_std[0] == pytest.approx(2.0, rel=0.03) and y_std[0] == pytest.approx(0.5, rel=0.03)



@pytest.mark.parametrize("scale", [1e-9, 1e-6, 1.0, 1e6, 1e9])
def test_constancy_is_decided_on_each_channels_own_scale(scale):
    """The units of one channel never change the verdict on another: an input with std 1e-6
    next to an output in 1e6 units is a signal, and a constant (with rounding noise on its
    own scale) is constant whatever the others' units."""
    rng = np.random.default_rng(4)
    u = rng.normal(size=(500, 2)) * [1e-6, 1.0]
    y = rng.normal(size=(500, 2)) * [1.0, scale]
    u_std, y_std = check_excited([sysid.IOData(u=u, y=y, dt=0.01)])
    assert u_std[0] == pytest.approx(1e-6, rel=0.1) and y_std[1] == pytest.approx(scale, rel=0.1)
    flat = u.copy()
    flat[:, 1] = 1500.0 * (1.0 + 1e-15 * rng.normal(size=500))  # constant, last-bit jitter
    with pytest.raises(DataError, match=r"input channel 1 \('u1'\) is constant"):
        check_excited([sysid.IOData(u=flat, y=y, dt=0.01)])


def test_a_switching_input_is_not_mistaken_for_the_rounding_left_by_detrending():
    """A 0/1 input takes two values spaced by a power of two, as what linear detrending leaves
    of a constant does; only the latter is far below every other channel."""
    rng = np.random.default_rng(5)
    u = np.column_stack([rng.integers(0, 2, 600).astype(float), rng.normal(size=600)])
    check_excited([sysid.IOData(u=u, y=rng.normal(size=(600, 1)), dt=0.01)])
    u[:, 0] *= 2.0 ** -60  # the same pattern at the rounding level of the others
    with pytest.raises(DataError, match=r"input channel 0 .* is constant"):
        check_excited([sysid.IOData(u=u, y=rng.normal(size=(600, 1)), dt=0.01)])


@pytest.mark.parametrize(("make", "words"), [
    (lambda u, y: (np.column_stack([u, 0.5 * u[:, 0] - 2.0 * u[:, 1]]), y),
     ["input channel 2 ('u2') is a linear combination of input channel 0 ('u0'), input "
      "channel 1 ('u1')", "drop redundant channels"]),
    (lambda u, y: (u, np.column_stack([y[:, 0], u[:, 1]])),
     ["output channel 1 ('y1')", "input channel 1 ('u1')", "rank deficient"]),
    # an offset hid it (degenerate-data review: y = -3 u + 2 gave a -390 % model, silently)
    (lambda u, y: (u, np.column_stack([y[:, 0], 2.0 - 3.0 * u[:, 0]])),
     ["output channel 1 ('y1') is a linear combination of input channel 0 ('u0')"]),
])
def test_channels_dependent_at_every_sample_are_named(make, words):
    rng = np.random.default_rng(6)
    u, y = make(rng.normal(size=(400, 2)), rng.normal(size=(400, 2)))
    with pytest.raises(DataError) as err:
        check_excited([sysid.IOData(u=u, y=y, dt=0.01)])
    msg = str(err.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"dt": "abc"}, "dt is 'abc'; pass the sample period"),
    ({"dt": None}, "dt is None; pass the sample period"),
    ({"dt": [0.01]}, "dt is [0.01]; pass the sample period"),
    ({"u": ["a"] * 10}, "u is not an array of real numbers (text, not numbers)"),
    ({"u": [[1.0, 2.0]] * 9 + [[3.0]]}, "u is not an array of real numbers"),
    ({"u": np.arange(10) * (1 + 1j)}, "u is not an array of real numbers (complex values)"),
])
def test_values_that_are_no_real_numbers_are_one_line_data_errors(kwargs, words):
    """A bare ValueError or TypeError from numpy before, and a complex input lost its imaginary
    part with only numpy's warning (degenerate-data review)."""
    args = {"u": np.arange(10.0), "y": np.arange(10.0) ** 2, "dt": 0.1, **kwargs}
    with pytest.raises(DataError) as err:
        sysid.IOData(**args)
    assert str(err.value).startswith(words) and "\n" not in str(err.value)


@pytest.mark.parametrize(("kwargs", "words"), [
    ({"dt": np.True_}, "dt is True"),
    ({"u": [["1.5"]] * 10}, "u is not an array of real numbers (text, not numbers)"),
    ({"u": np.array([1.0, "a"] * 5, dtype=object)}, "u is not an array of real numbers (text"),
])
def test_numpy_booleans_and_numeric_text_are_refused_too(kwargs, words):
    """numpy read "1.5" as 1.5 and np.True_ as a 1 s period (review)."""
    args = {"u": np.arange(10.0), "y": np.arange(10.0) ** 2, "dt": 0.1, **kwargs}
    with pytest.raises(DataError, match=re.escape(words)):
        sysid.IOData(**args)
