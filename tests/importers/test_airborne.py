"""Airborne segments: the pure detector on constructed logs, and on the real CrazyPAD flights."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.importers import read_usd
from groundstation.importers.airborne import Segment, airborne_segments, find_segments
from groundstation.importers.to_session import ImportedBlock
from tests.paths import CRAZYPAD

DT = 0.01


def flight_log(*, flights: list[tuple[float, float]], hover_m: float = 0.5, ramp_s: float = 1.0,
               length_s: float = 30.0, ground_m: tuple[float, ...] = (0.0, 0.0, 0.0)):
    """100 Hz log: motors on at 40000 from each ``(on, off)``; height ramps linearly up
    ``ramp_s`` after motor start and down ``ramp_s`` before motor stop; on the ground the
    estimate reads ``ground_m[k]`` before flight k (the estimator drifts between flights)."""
    t = np.arange(0.0, length_s, DT)
    thrust = np.zeros_like(t)
    height = np.full_like(t, ground_m[0])
    for k, (on, off) in enumerate(flights):
        g0, g1 = ground_m[k], ground_m[k + 1]
        m = (t >= on) & (t < off)
        thrust[m] = 40000.0
        up = np.clip((t - on) / ramp_s, 0, 1)
        down = np.clip((off - t) / ramp_s, 0, 1)
        height[m] = g0 + hover_m * np.minimum(up, down)[m]
        height[t >= off] = g1
    return t, thrust, height


def test_two_flights_with_height_give_two_segments_inside_the_hover():
    # hover 0.5 m: half height is reached 0.5 s after motor start / before motor stop; the
    # 0.75 s guard then moves each end 0.75 s further in
    t, thrust, h = flight_log(flights=[(2.0, 10.0), (15.0, 25.0)], ground_m=(0.0, 0.09, 0.09))
    segs = airborne_segments(t_s=t, thrust=thrust, height_m=h)
    assert len(segs) == 2
    for seg, (on, off) in zip(segs, [(2.0, 10.0), (15.0, 25.0)], strict=True):
        assert seg.start_s == pytest.approx(on + 0.5 + 0.75, abs=2 * DT)
        assert seg.end_s == pytest.approx(off - 0.5 - 0.75, abs=2 * DT)
        inside = (t >= seg.start_s) & (t <= seg.end_s)
        assert np.all(thrust[inside] > 0)  # motors on throughout, ground excluded


def test_a_dip_below_half_height_is_no_landing_but_touching_down_is():
    """A flight that sank from 1.3 m to 0.5 m in its excitation was cut in two segments, the
    first 3 s long (first-day review); touching down between two hops still splits."""
    t, thrust, h = flight_log(flights=[(2.0, 25.0)], hover_m=1.3)
    sank = (t > 8.0) & (t < 15.0)
    h[sank] = 0.5
    [seg] = airborne_segments(t_s=t, thrust=thrust, height_m=h)
    assert seg.start_s < 8.0 and seg.end_s > 15.0
    h[sank] = 0.02  # down on the ground with the motors on
    segs = airborne_segments(t_s=t, thrust=thrust, height_m=h)
    assert len(segs) == 2 and segs[0].end_s < 8.0 < 15.0 < segs[1].start_s


def test_without_height_the_motor_runs_are_trimmed_by_a_second():
    t, thrust, _ = flight_log(flights=[(2.0, 10.0)])
    [seg] = airborne_segments(t_s=t, thrust=thrust)
    assert seg == Segment(pytest.approx(3.0), pytest.approx(10.0 - DT - 1.0))


def test_motors_on_the_ground_and_short_hops_are_no_flights():
    t, thrust, h = flight_log(flights=[(2.0, 10.0)], hover_m=0.05)  # never 0.10 m up
    assert airborne_segments(t_s=t, thrust=thrust, height_m=h) == []
    t, thrust, h = flight_log(flights=[(2.0, 5.0)])  # 3 s on, 1.75 s above half height
    assert airborne_segments(t_s=t, thrust=thrust, height_m=h) == []  # 0.25 s after the guards
    t, thrust, h = flight_log(flights=[(2.0, 3.5)])
    assert airborne_segments(t_s=t, thrust=thrust) == []  # 1.5 s on, -0.5 s after trimming


def test_idle_thrust_is_motors_off():
    t, thrust, h = flight_log(flights=[(2.0, 10.0)])
    idle = np.where(thrust > 0, thrust, 5000.0)  # below 10 000: armed, not flying
    assert airborne_segments(t_s=t, thrust=idle, height_m=h) == airborne_segments(
        t_s=t, thrust=thrust, height_m=h)


def test_a_log_ending_in_the_air_ends_its_segment_before_the_end():
    t, thrust, h = flight_log(flights=[(2.0, 40.0)], length_s=12.0)
    [seg] = airborne_segments(t_s=t, thrust=thrust, height_m=h)
    assert seg.end_s == pytest.approx(t[-1] - 0.75)


def test_nan_and_disorder_never_raise():
    t, thrust, h = flight_log(flights=[(2.0, 10.0)])
    full = airborne_segments(t_s=t, thrust=thrust, height_m=h)
    thrust[500:510] = np.nan  # a 0.1 s thrust dropout is not a landing
    assert airborne_segments(t_s=t, thrust=thrust, height_m=h) == full
    h[300:310] = np.nan  # unknown height counts as not airborne: the segment starts after it
    [seg] = airborne_segments(t_s=t, thrust=thrust, height_m=h)
    assert seg.start_s == pytest.approx(3.1 + 0.75) and seg.end_s == full[0].end_s
    assert airborne_segments(t_s=t[::-1].copy(), thrust=thrust, height_m=h) == []
    assert airborne_segments(t_s=t[:1], thrust=thrust[:1]) == []
    with pytest.raises(ValueError, match="shaped like"):
        airborne_segments(t_s=t, thrust=thrust, height_m=h[:-1])


def test_find_segments_picks_motors_and_height_from_another_block_in_mm():
    t, thrust, h = flight_log(flights=[(2.0, 10.0)])
    motors = ImportedBlock("Motors", t, {f"motor.m{i}": thrust.astype(np.uint16)
                                         for i in range(1, 5)}, {})
    tz = t[::2] + 0.003  # 50 Hz, another clock phase
    ranger = ImportedBlock("Range", tz, {"range.zrange": np.interp(tz, t, h) * 1000.0}, {})
    segs, how = find_segments([ranger, motors])
    assert segs == airborne_segments(t_s=t, thrust=thrust, height_m=h) != []
    assert "motor.m1, motor.m2" in how and "height range.zrange" in how
    assert find_segments([ranger]) == ([], find_segments([ranger])[1])
    assert "no thrust logged" in find_segments([ranger])[1]


@pytest.mark.skipif(not CRAZYPAD.is_dir(), reason="shared CrazyPAD logs not present")
@pytest.mark.parametrize("log", ["controller_E8_log00", "controller_E8_log01", "motor_E8_log00"])
def test_crazypad_flights_have_two_hover_segments(log):
    """Each log holds two hovers at about 0.53 m with motors off (0 thrust) between them."""
    ev = read_usd(CRAZYPAD / log).events["fixedFrequency"]
    segs, how = find_segments([ev])
    assert len(segs) == 2, how
    t, z = ev.timestamps_s, ev.values["stateEstimate.z"].astype(float)
    names = (["controller.cmd_thrust"] if "controller.cmd_thrust" in ev.values
             else [f"motor.m{i}" for i in range(1, 5)])
    thrust = np.mean([ev.values[n].astype(float) for n in names], axis=0)
    for seg in segs:
        inside = (t >= seg.start_s) & (t <= seg.end_s)
        hover = np.median(z[inside])
        assert 0.50 < hover < 0.56 and seg.end_s - seg.start_s > 5.5
        assert z[inside].min() > hover - 0.1 and thrust[inside].min() > 30000  # flying
        # the landing: height falls 5 cm below the hover only after the segment has ended
        after = (t > seg.end_s) & (t < seg.end_s + 2.0)
        below = np.flatnonzero(z[after] < hover - 0.05)
        assert len(below) and t[after][below[0]] > seg.end_s + 0.2
