"""groundstation/plan/schedule.py on a hand-made schedule: setpoint times k / f, phases, the abort
descent, and the checks that refuse an inconsistent schedule."""
from __future__ import annotations

import numpy as np
import pytest

from groundstation.errors import PlanError
from groundstation.plan.schedule import Phase, Safety, Schedule, VehicleLimits

RATE = 20.0
VEHICLE = VehicleLimits(max_roll_deg=30.0, max_pitch_deg=30.0, max_yaw_rate_deg_s=200.0,
                        thrust_min=0, thrust_max=60000, min_vbat=3.7)


def _schedule(*, safety: Safety | None = None, phase_id: np.ndarray | None = None) -> Schedule:
    phases = (Phase(id=0, name="up", kind="takeoff", start_tick=0, end_tick=10, rate_hz=RATE),
              Phase(id=1, name="x", kind="excitation", start_tick=10, end_tick=50, rate_hz=RATE),
              Phase(id=2, name="down", kind="landing", start_tick=50, end_tick=60, rate_hz=RATE))
    roll = np.where(np.arange(60) % 7 == 0, 10.0, 0.0)
    return Schedule(name="s", rate_hz=RATE, roll=roll, pitch=np.zeros(60), yaw_rate=np.zeros(60),
                    thrust=np.linspace(20000, 45000, 60).astype(int),
                    phase_id=np.repeat([0, 1, 2], [10, 40, 10]) if phase_id is None else phase_id,
                    phases=phases, vehicle=VEHICLE, safety=safety or Safety())


def test_setpoint_k_is_at_k_over_the_rate():
    s = _schedule()
    assert len(s) == 60 and s.duration == pytest.approx(3.0) and s.period == pytest.approx(0.05)
    np.testing.assert_array_equal(s.t, np.arange(60) / RATE)  # t0 + k / f, never a running sum
    assert s.setpoint(7) == (10.0, 0.0, 0.0, int(s.thrust[7]))
    assert s.as_array().shape == (60, 4)


def test_phases_map_ticks_and_times():
    s = _schedule()
    assert [s.phase_at(k).name for k in (0, 9, 10, 49, 50, 59)] == ["up", "up", "x", "x",
                                                                     "down", "down"]
    x = s.phases[1]
    assert (x.start, x.end, x.duration, x.n_ticks) == (0.5, 2.5, 2.0, 40)
    assert s.to_dict()["phases"][2] == {"id": 2, "name": "down", "kind": "landing",
                                        "start_s": 2.5, "end_s": 3.0, "start_tick": 50,
                                        "end_tick": 60}


def test_abort_descends_level_at_the_lower_thrust():
    s = _schedule(safety=Safety(on_abort="descend", descent_duration=0.5, descent_thrust=30000))
    high = s.abort_schedule(55)  # planned thrust above descent_thrust: descend at descent_thrust
    assert len(high) == 10 and set(high.thrust) == {30000}
    assert not (high.roll.any() or high.pitch.any() or high.yaw_rate.any())
    assert [p.kind for p in high.phases] == ["abort"]
    low = s.abort_schedule(2)  # during a low take-off ramp: never climb
    assert set(low.thrust) == {int(s.thrust[2])} and s.thrust[2] < 30000
    assert len(s.abort_schedule(60)) == 0  # at the end: stop at once
    assert len(_schedule().abort_schedule(20)) == 0  # on_abort = "stop"


def test_inconsistent_schedules_are_refused():
    bad = np.repeat([0, 1, 2], [10, 40, 10])
    bad[12] = 0
    with pytest.raises(PlanError, match="phase_id disagrees with phase 'x'"):
        _schedule(phase_id=bad)
    with pytest.raises(PlanError, match=r"roll = 40 deg at t = 0\.1 s violates vehicle\.max_roll"):
        Schedule(name="s", rate_hz=RATE, roll=np.array([0.0, 0.0, 40.0]), pitch=np.zeros(3),
                 yaw_rate=np.zeros(3), thrust=np.zeros(3, dtype=int), phase_id=np.zeros(3),
                 phases=(Phase(id=0, name="h", kind="hover", start_tick=0, end_tick=3,
                               rate_hz=RATE),), vehicle=VEHICLE)
