"""The ground-station altitude hold keeps a simulated vehicle airborne through the PRBS."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.errors import PlanError
from groundstation.plan import load_plan, parse_plan
from groundstation.plan.altitude import AltitudeHold, AltitudeHoldConfig
from groundstation.sim.vehicle import SimVehicle


def fly(schedule, *, hold: bool, seconds: float, seed: int = 1):
    """Stream the schedule into the vehicle as the runner would; return altitude per tick."""
    v = SimVehicle(seed=seed)
    v.commander_rpyt(roll=0.0, pitch=0.0, yawrate=0.0, thrust=0)  # release the thrust lock
    ctl = AltitudeHold(schedule.altitude_hold, period_s=1 / schedule.rate_hz)
    z = []
    for k in range(int(seconds * schedule.rate_hz)):
        kind = schedule.phases[schedule.phase_id[k]].kind
        trim = ctl.update(z=v.read_log("stateEstimate.z"),
                          active=hold and kind in schedule.altitude_hold.kinds)
        v.commander_rpyt(roll=float(schedule.roll[k]), pitch=-float(schedule.pitch[k]),
                         yawrate=float(schedule.yaw_rate[k]), thrust=int(schedule.thrust[k]) + trim)
        v.advance(1 / schedule.rate_hz)
        z.append(v.position_m[2])
    return np.array(z)


def test_hold_keeps_the_prbs_flight_at_its_target_height():
    s = load_plan("prbs-3axis").compile()
    excitation = next(p for p in s.phases if p.kind == "excitation")
    seconds = excitation.start + 30.0
    free = fly(s, hold=False, seconds=seconds)
    held = fly(s, hold=True, seconds=seconds)
    window = slice(excitation.start_tick + 30, None)  # after 3 s of PRBS
    assert free[window].max() < 0.05, "open-loop thrust should sink to the ground (else no test)"
    assert held[excitation.start_tick :].min() > 0.3  # never back in ground effect
    assert abs(np.mean(held[window]) - s.altitude_hold.target_m) < 0.15
    assert held[window].std() < 0.25


def test_integral_action_removes_a_constant_thrust_error():
    cfg = AltitudeHoldConfig(target_m=1.0)
    ctl = AltitudeHold(cfg, period_s=0.1)
    # vertical double integrator with a 2000 PWM thrust deficit; 4.3e-4 m/s^2 per PWM
    z, vz = 1.0, 0.0
    for _ in range(600):
        a = 4.3e-4 * (ctl.update(z=z, active=True) - 2000)
        vz += a * 0.1
        z += vz * 0.1
    assert z == pytest.approx(1.0, abs=0.02) and ctl.trim == pytest.approx(2000, abs=100)
    assert ctl.update(z=z, active=False) == 0 and ctl.trim == 0  # leaving a held phase resets


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ('kinds = ["takeoff"]', "kinds"),
        ("max_trim = 30000", "max_trim"),
        ('variable = "z"', "not a log variable"),
        ("kp = -1", "kp"),
        ("gain = 3", "gain"),
    ],
)
def test_bad_altitude_hold_tables_are_refused_with_their_line(table, message):
    text = load_plan("hover-check").text
    start = text.index("[altitude_hold]")
    line = text[:start].count("\n") + 2
    bad = text.replace("[altitude_hold]", f"[altitude_hold]\n{table}", 1)
    bad = bad.replace("\nmax_trim = 12000 ", "\n# ", 1) if "max_trim" in table else bad
    bad = bad.replace("\nkp = 4000 ", "\n# ", 1) if "kp" in table else bad
    bad = bad.replace('\nvariable = "stateEstimate.z"', "\n# ", 1) if "variable" in table else bad
    with pytest.raises(PlanError) as info:
        parse_plan(text=bad, source="p.toml")
    assert message in str(info.value) and "\n" not in str(info.value)
    if "kinds" in table or "gain" in table:
        assert f"p.toml:{line}:" in str(info.value)


def test_safety_max_rate_is_read_and_bounded():
    text = load_plan("roll-only").text
    plan = parse_plan(text=text.replace("[safety]\n", "[safety]\nmax_rate_deg_s = 400\n", 1))
    assert plan.compile().safety.max_rate_deg_s == 400.0
    assert load_plan("roll-only").compile().safety.max_rate_deg_s is None  # runner default
    with pytest.raises(PlanError, match="max_rate_deg_s"):
        parse_plan(text=text.replace("[safety]\n", "[safety]\nmax_rate_deg_s = 1\n", 1))


def test_a_hover_thrust_beyond_the_trim_range_names_both_terms_lines():
    """The sum is refused on max_trim's line and names hover_thrust's, the term a user who
    measured a heavier vehicle's hover thrust just changed."""
    text = load_plan("hover-check").text
    hover_line = next(i for i, s in enumerate(text.splitlines(), 1)
                      if s.startswith("hover_thrust ="))
    bad = text.replace("\nhover_thrust = 39000 ", "\nhover_thrust = 58000 ", 1)
    with pytest.raises(PlanError) as info:
        parse_plan(text=bad, source="p.toml")
    assert f"hover_thrust 58000 (line {hover_line}) ± max_trim 12000 = 70000 PWM" in str(
        info.value)
