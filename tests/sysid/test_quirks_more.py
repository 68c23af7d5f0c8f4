"""Data checks: quantised outputs are named; huge magnitudes raise no overflow."""

from __future__ import annotations

import logging
import warnings
from functools import partial

import numpy as np
import pytest

import sysid
from sysid.data import check_magnitudes
from sysid.quirks import (
    QUANT_NOISE,
    data_warnings,
    find_outliers,
    find_quantised,
    quantisation_warnings,
)
from tests.sysid.systems import open_loop, random_stable_system


def _experiment(n: int = 1500, *, seed: int = 0) -> sysid.IOData:
    rng = np.random.default_rng(seed)
    system = random_stable_system(n_states=4, n_inputs=1, n_outputs=2, rng=rng,
                                  radius=(0.6, 0.9))
    return open_loop(system, n_samples=n, rng=rng, noise_std=0.02).data


def _rounded(data: sysid.IOData, levels: int) -> sysid.IOData:
    """Output 0 rounded onto ``levels`` levels across its range."""
    y = np.array(data.y)
    lo, hi = y[:, 0].min(), y[:, 0].max()
    step = (hi - lo) / (levels - 1)
    y[:, 0] = np.round((y[:, 0] - lo) / step) * step + lo
    return sysid.IOData(u=data.u, y=y, dt=data.dt, output_names=["alt", "rate"],
                        output_units=["m", "rad/s"])


def test_a_quantised_output_is_named_with_its_levels_step_and_fit_bound() -> None:
    """An output rounded to 6 levels (step 1.26 standard deviations: the selection chose
    order 7 for a true 4) and to 16 (0.45: order 10) is named with its levels, step and the
    fit its rounding allows; 35 levels (0.17: order 4) and the unrounded output are not."""
    clean = _experiment()
    assert quantisation_warnings([clean]) == []
    (q,) = find_quantised([_rounded(clean, 6)])
    assert (q.name, q.column, q.levels) == ("alt", 0, 6)
    assert q.noise == pytest.approx(1.26 / np.sqrt(12), rel=0.05)
    (line,) = quantisation_warnings([_rounded(clean, 6)])
    assert "\n" not in line and line.startswith("output alt is quantised: 6 levels")
    assert f"a step of {q.step:.3g} m" in line and "step^2/12" in line
    assert f"bounded near {100 * (1 - q.noise):.0f} %" in line and "finer resolution" in line
    assert [w.startswith("output alt is quantised") for w in data_warnings(
        [_rounded(clean, 16)])] == [True]
    assert find_quantised([_rounded(clean, 35)]) == []


def test_excitation_inputs_on_few_levels_and_short_continuous_records_are_not_flagged() -> None:
    """A PRBS (2 levels) and a held staircase (5 levels) are inputs by design: not flagged; an
    on/off output is (2 levels); 8 continuous samples are not a grid."""
    rng = np.random.default_rng(1)
    n = 2000
    prbs = np.sign(rng.standard_normal(n // 10).repeat(10))
    stairs = rng.integers(0, 5, n // 50).repeat(50).astype(float)
    y = np.convolve(prbs + stairs, np.ones(4) / 4, "same")
    data = sysid.IOData(u=np.column_stack([prbs, stairs]),
                        y=np.column_stack([y, y > 0.5]), dt=0.01)
    (q,) = find_quantised([data])
    assert (q.name, q.levels) == ("y1", 2) and q.noise > QUANT_NOISE
    short = sysid.IOData(u=rng.standard_normal(8), y=rng.standard_normal(8), dt=1.0)
    assert find_quantised([short]) == []


def test_huge_or_tiny_magnitudes_raise_no_overflow_and_are_refused_in_one_line() -> None:
    """Data times 1e300 overflowed the squares of the data checks (RuntimeWarnings from
    sysid.quirks) and ended in a false 'linear combination' refusal. Every check of the
    records (sysid.data.as_flights) now refuses magnitudes whose sums of squares overflow or
    underflow, naming the channel, and what it lets through (1e140, 1e-140) finds the same
    outliers without a warning."""
    clean = _experiment(n=600, seed=2)
    y = np.array(clean.y)
    y[300, 1] += 30 * y[:, 1].std()
    spiked = sysid.IOData(u=clean.u, y=y, dt=clean.dt)
    where = [o.where for o in find_outliers([spiked])]
    assert where == [((0, 300),)]
    for scale in (1e140, 1e-140):  # squares in range, sums of squares near the edge
        data = sysid.IOData(u=clean.u, y=y * scale, dt=clean.dt)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            assert [o.where for o in find_outliers([data])] == where
            assert len(data_warnings([data])) == 1
    for scale in (1e300, 1e-320):
        data = sysid.IOData(u=clean.u, y=y * scale, dt=clean.dt)
        calls = ((sysid.identify, data), (find_outliers, [data]),
                 (partial(sysid.iem, order=4, past=10, future=10), data))
        for call, arg in calls:  # no knobs, the data checks and a fixed-knob method alike
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                with pytest.raises(sysid.DataError, match=r"^output channel 0 \('y0'\) .*"
                                                          r"rescale it \(another unit\)") as err:
                    call(arg)
            assert "\n" not in str(err.value)
    check_magnitudes([spiked])  # ordinary data pass


def test_channels_far_from_zero_are_named_with_the_mean_removal_as_remedy() -> None:
    """An input around an operating point (hover thrust: 40 000 counts +- 2 000) and an
    output with a bias: named, with their means and how many standard deviations out; the
    same data with the means removed, or a step from rest (mean 0.5, SD 0.5), are not."""
    from sysid.quirks import find_offsets, offset_warnings

    rng = np.random.default_rng(2)
    system = random_stable_system(n_states=3, n_inputs=2, n_outputs=2, rng=rng,
                                  radius=(0.5, 0.9))
    data = open_loop(system, n_samples=1500, rng=rng, noise_std=0.05).data
    u = data.u * np.array([2000.0, 1.0]) + np.array([40_000.0, 0.0])
    y = data.y + np.array([0.0, 10.0 * data.y[:, 1].std()])
    raw = sysid.IOData(u=u, y=y, dt=0.01, input_names=["thrust", "roll"],
                       output_names=["gyro.x", "acc.z"], input_units=["PWM", "deg"],
                       output_units=["deg/s", "g"])
    found = find_offsets([raw])
    assert [(o.kind, o.name) for o in found] == [("input", "thrust"), ("output", "acc.z")]
    assert 19 < found[0].ratio < 21 and 9 < found[1].ratio < 11
    (line,) = offset_warnings([raw])
    assert f"input thrust {found[0].mean:.4g} PWM ({found[0].ratio:.1f} SD)" in line
    assert "output acc.z" in line
    assert "--detrend mean" in line and "\n" not in line
    assert line in data_warnings([raw])
    centred = sysid.IOData(u=u - u.mean(axis=0), y=y - y.mean(axis=0), dt=0.01)
    assert find_offsets([centred]) == []
    steps = np.repeat([[0.0, 0.0], [1.0, 1.0]], 750, axis=0)  # both inputs step at rest
    assert find_offsets([sysid.IOData(u=steps, y=system.simulate(steps), dt=0.01)]) == []
    # a step held for a share a of the record sits sqrt(a / (1 - a)) SD out: named beyond 90 %
    for share, named in ((0.85, False), (0.95, True)):
        u = np.zeros((1000, 2))
        u[round(1000 * (1 - share)):, 0] = 1.0
        found = find_offsets([sysid.IOData(u=u, y=system.simulate(u), dt=0.01)])
        assert ("u0" in [o.name for o in found]) is named, (share, found)


def test_the_offset_warning_of_the_products_is_logged_once(caplog) -> None:
    """A selection builds the products of the same data several times (held-out split, the
    grid, the refit): the raw-API user saw the same warning three times."""
    rng = np.random.default_rng(11)
    u = 7.25 + rng.standard_normal((600, 1))  # an offset no other test uses: logged afresh
    y = np.convolve(u[:, 0] - 7.25, [0.0, 0.5, 0.3], mode="full")[:600, None] + 3.5
    with caplog.at_level(logging.WARNING, logger="sysid.factor"):
        sysid.identify(sysid.IOData(u=u, y=y, dt=0.1), orders=[2], pasts=[4], futures=[4])
    said = [r.getMessage() for r in caplog.records if r.name == "sysid.factor"]
    assert len(said) == 1 and said[0].startswith("channels far from zero mean: u0 (mean 7.2")
