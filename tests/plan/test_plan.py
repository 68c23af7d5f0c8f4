"""Loading, validating and compiling flight plans; every error names key and line."""

from __future__ import annotations

import json
import re
import tomllib

import numpy as np
import pytest

from groundstation.errors import PlanError
from groundstation.plan import SHIPPED_PLANS_DIR, Schedule, find_plan, load_plan, parse_plan
from groundstation.plan.excitation import mls_bits, prbs_shift
from tests.plan.conftest import BASE, line_of

SHIPPED = sorted(SHIPPED_PLANS_DIR.glob("*.toml"))


def test_the_five_thesis_plans_are_shipped():
    names = {p.stem for p in SHIPPED}
    assert {"prbs-3axis", "pitch-only", "roll-only", "yaw-only", "hover-check"} <= names


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.stem)
def test_shipped_plan_loads_and_compiles_to_its_timeline(path):
    raw = tomllib.loads(path.read_text())
    plan = load_plan(path)
    sched = plan.compile()
    rate = raw.get("setpoint_rate_hz", 10)
    durations = [p["duration"] for p in raw["phase"]]
    assert plan.text == path.read_text() and plan.name == raw["name"] == path.stem
    assert len(sched) == round(sum(durations) * rate) == plan.n_setpoints
    assert sched.duration == pytest.approx(sum(durations))
    np.testing.assert_array_equal(sched.t, np.arange(len(sched)) / rate)
    assert [p.name for p in sched.phases] == [p["name"] for p in raw["phase"]]
    ends = np.cumsum(durations)
    for phase, end, dur in zip(sched.phases, ends, durations, strict=True):
        assert phase.end == pytest.approx(end) and phase.duration == pytest.approx(dur)
        assert np.all(sched.phase_id[phase.start_tick : phase.end_tick] == phase.id)
    v = raw["vehicle"]
    assert np.all((sched.thrust >= v["thrust_min"]) & (sched.thrust <= v["thrust_max"]))
    assert np.abs(sched.roll).max() <= v["max_roll_deg"]
    assert np.abs(sched.pitch).max() <= v["max_pitch_deg"]
    assert np.abs(sched.yaw_rate).max() <= v["max_yaw_rate_deg_s"]
    assert sched.phases[0].kind == "takeoff" and sched.phases[-1].kind == "landing"
    assert json.loads(json.dumps(sched.to_dict()))["n_setpoints"] == len(sched)


def test_prbs_3axis_matches_the_thesis_design():
    sched = load_plan("prbs-3axis").compile()
    ph = next(p for p in sched.phases if p.kind == "excitation")
    seg = slice(ph.start_tick, ph.end_tick)
    assert ph.duration >= 60.0  # long enough for an 8th-order model, p = 60, f = 17 at 50 Hz
    assert set(np.unique(sched.roll[seg])) == {-25.0, 25.0}
    assert set(np.unique(sched.pitch[seg])) == {-25.0, 25.0}
    assert set(np.unique(sched.yaw_rate[seg])) == {-50.0, 50.0}
    assert np.all(sched.thrust[seg] == 39000)
    # Pairwise uncorrelated (normalised periodic cross-correlation) at every lag up to 20 ticks
    # (2 s: the identification horizons, 77 samples at 50 Hz, are 1.54 s).
    axes = [sched.roll[seg] / 25, sched.pitch[seg] / 25, sched.yaw_rate[seg] / 50]
    for i in range(3):
        for j in range(i + 1, 3):
            for lag in range(-20, 21):
                r = np.mean(axes[i] * np.roll(axes[j], lag))
                assert abs(r) < 2e-3, (i, j, lag, r)
    # And the roll axis is the m-sequence from its seed, chip for chip.
    np.testing.assert_array_equal(sched.roll[seg] > 0, mls_bits(register_length=10, seed=1) == 1)
    assert prbs_shift(register_length=10, seed_a=1, seed_b=441) == 341


def test_hover_check_ramps_and_hover_values():
    sched = load_plan(find_plan("hover-check")).compile()
    up, hover, down = sched.phases
    assert (up.start, up.end, hover.end, down.end) == (0.0, 2.0, 7.0, 10.0)
    assert sched.thrust[0] == 20000 and sched.thrust[up.end_tick - 1] == 42000
    np.testing.assert_array_equal(np.diff(sched.thrust[: up.end_tick]) > 0, True)
    assert np.all(sched.thrust[hover.start_tick : hover.end_tick] == 39000)
    assert sched.thrust[down.start_tick] == 36000 and sched.thrust[-1] == 20000
    assert sched.setpoint(50) == (0.0, 0.0, 0.0, 39000)
    assert sched.as_array().shape == (100, 4)
    with pytest.raises(ValueError):
        sched.thrust[0] = 0  # read-only: the runner cannot alter the plan


def test_base_plan_compiles_doublet_and_prbs():
    sched = parse_plan(text=BASE, source="base.toml").compile()
    ph = sched.phases[1]
    yaw = sched.yaw_rate[ph.start_tick : ph.end_tick]
    np.testing.assert_array_equal(yaw[:7], [0, 0, 40, 40, 40, 40, 40])
    np.testing.assert_array_equal(yaw[7:13], [-40] * 5 + [0])
    roll = sched.roll[ph.start_tick : ph.end_tick]
    assert roll.size == 31 and roll.sum() == 20.0  # one period: one more +A than -A


def test_abort_descends_level_at_capped_thrust_then_stops():
    sched = parse_plan(text=BASE).compile()
    mid = sched.phases[1].start_tick + 5
    abort = sched.abort_schedule(mid)
    assert len(abort) == 10 and abort.phases[0].kind == "abort"
    assert np.all(abort.thrust == min(sched.thrust[mid], 34000))
    assert not abort.roll.any() and not abort.pitch.any() and not abort.yaw_rate.any()
    assert np.all(sched.abort_schedule(0).thrust == 20000)  # never climbs during take-off
    assert len(sched.abort_schedule(len(sched))) == 0
    stop = parse_plan(text=BASE.replace('on_abort = "descend"', 'on_abort = "stop"')).compile()
    assert len(stop.abort_schedule(mid)) == 0


def _error(text: str) -> str:
    with pytest.raises(PlanError) as info:
        parse_plan(text=text, source="p.toml")
    msg = str(info.value)
    assert "\n" not in msg
    return msg


@pytest.mark.parametrize(
    ("old", "new", "key", "needles"),
    [
        (
            "amplitude = 20.0",
            "amplitude = 35.0",
            "phase[1].roll.amplitude",
            ["35", "vehicle.max_roll_deg (line 6) = 30"],
        ),
        (
            "amplitude = 40.0",
            "amplitude = 250.0",
            "phase[1].yaw_rate.amplitude",
            ["250", "vehicle.max_yaw_rate_deg_s (line 8) = 200"],
        ),
        (
            "hover_thrust = 39000",
            "hover_thrust = 61000",
            "hover_thrust",
            ["61000", "vehicle.thrust_max (line 10) = 60000"],
        ),
        (
            "descent_thrust = 34000",
            "descent_thrust = 5000",
            "safety.descent_thrust",
            ["5000", "vehicle.thrust_min (line 9) = 10000"],
        ),
        (
            "thrust_end = 42000",
            "thrust_end = 62000",
            "phase[0].thrust_end",
            ["62000", "thrust_max"],
        ),
        (
            "[phase.yaw_rate]",
            '[phase.thrust]\nsignal = "step"\namplitude = 25000\n[phase.yaw_rate]',
            "phase[1].thrust.amplitude",
            ["64000", "thrust_max"],
        ),
    ],
)
def test_out_of_limit_values_are_refused_with_key_value_limit_and_line(old, new, key, needles):
    text = BASE.replace(old, new, 1)
    msg = _error(text)
    first = new.splitlines()[-1] if new.startswith("[phase.thrust]") else new
    needle = "amplitude = 25000" if new.startswith("[phase.thrust]") else first
    assert msg.startswith(f"p.toml:{line_of(text, needle)}: {key}: "), msg
    for n in needles:
        assert n in msg, msg


def test_malformed_toml_gives_one_line_error_with_line():
    text = BASE.replace("duration = 3.1", 'duration = "3.1')
    msg = _error(text)
    line = line_of(text, 'duration = "3.1')
    assert msg.startswith(f"p.toml:{line}: invalid TOML"), msg


@pytest.mark.parametrize(
    ("old", "new", "hint"),
    [
        ("amplitude = 20.0", "amplitud = 20.0", "did you mean 'amplitude'?"),
        ("hover_thrust = 39000", "hover_thrust = 39000\nhover_thrus = 1", "'hover_thrust'"),
        ("max_roll_deg = 30.0", "max_roll_deg = 30.0\nmax_rol_deg = 3", "'max_roll_deg'"),
        ("seed = 3", "seed = 3\nclock = 2", "did you mean 'clock_period'?"),
        ('kind = "takeoff"', 'kind = "takeoff"\nthrust = 1', "allowed"),
    ],
)
def test_unknown_keys_are_refused_at_their_line(old, new, hint):
    text = BASE.replace(old, new, 1)
    bad = new.splitlines()[-1]
    msg = _error(text)
    assert msg.startswith(f"p.toml:{line_of(text, bad)}: "), msg
    assert f"unknown key '{bad.split(' =')[0]}'" in msg and hint in msg


@pytest.mark.parametrize(
    ("old", "new", "needle", "fragment"),
    [
        ("duration = 3.1", "duration = 3.05", "duration = 3.05", "use 3 or 3.1 s"),
        ("seed = 3", "seed = 32", "seed = 32", "<= 31"),
        ("register_length = 5", "period = 30", "period = 30", "not 2^n - 1"),
        ("register_length = 5", "register_length = 5\nperiod = 31", "[phase.roll]", "exactly one"),
        ("width = 0.5", "width = 1.5", "width = 1.5", "does not fit"),
        ('kind = "takeoff"', 'kind = "hover"', 'kind = "hover"', "must be 'takeoff'"),
        ('signal = "doublet"', 'signal = "sine"', 'signal = "sine"', "not one of"),
        ("min_vbat = 3.8", 'min_vbat = "3.8"', "min_vbat", "not a number (V)"),
        ('name = "down"', 'name = "up"', 'name = "up"', "already the name of phase[0]"),
        ("thrust_max = 60000", "thrust_max = 9000", "thrust_max", "> 10000"),
    ],
)
def test_schema_violations_name_key_and_line(old, new, needle, fragment):
    text = BASE.replace(old, new, 1)
    msg = _error(text)
    nth = 2 if needle == 'name = "up"' else 1
    assert msg.startswith(f"p.toml:{line_of(text, needle, nth)}: "), msg
    assert fragment in msg, msg


def test_a_plan_needs_takeoff_and_landing():
    text = BASE.split("[[phase]]")[0] + '[[phase]]\nkind = "takeoff"\nduration = 1.0\n'
    assert _error(text).startswith(f"p.toml:{line_of(text, '[[phase]]')}: phase: a plan needs")


def test_lines_survive_inline_tables_dotted_keys_and_multiline_strings():
    text = BASE.replace(
        'name = "base"', 'name = "base"\ndescription = """\n[[phase]]\namplitude = 1\n"""'
    ).replace(
        '[phase.roll]\nsignal = "prbs"\nregister_length = 5\namplitude = 20.0\nseed = 3\n',
        'roll = { signal = "prbs", register_length = 5, amplitude = 45.0 }\n',
    )
    msg = _error(text)
    assert msg.startswith(f"p.toml:{line_of(text, 'roll = {')}: phase[1].roll.amplitude"), msg
    dotted = BASE.replace("[phase.roll]\n", "").replace("amplitude = 20.0", "")
    dotted = (
        dotted.replace('signal = "prbs"', 'roll.signal = "prbs"')
        .replace("register_length = 5\n", "roll.register_length = 5\nroll.amplitude = 31\n")
        .replace("seed = 3", "roll.seed = 3")
    )
    msg = _error(dotted)
    assert msg.startswith(f"p.toml:{line_of(dotted, 'roll.amplitude')}: phase[1].roll"), msg


def test_missing_plan_names_the_shipped_ones(tmp_path):
    with pytest.raises(PlanError, match="hover-check"):
        load_plan(tmp_path / "nope.toml")


def test_a_hand_made_schedule_beyond_the_limits_is_refused():
    sched = parse_plan(text=BASE).compile()
    roll = sched.roll.copy()
    roll[12] = 31.0
    with pytest.raises(PlanError, match=r"roll = 31 deg at t = 1\.2 s violates vehicle\.max_roll"):
        Schedule(
            name="x",
            rate_hz=sched.rate_hz,
            roll=roll,
            pitch=sched.pitch,
            yaw_rate=sched.yaw_rate,
            thrust=sched.thrust,
            phase_id=sched.phase_id,
            phases=sched.phases,
            vehicle=sched.vehicle,
        )
    with pytest.raises(PlanError, match="phases cover"):
        Schedule(
            name="x",
            rate_hz=10.0,
            roll=[0.0],
            pitch=[0.0],
            yaw_rate=[0.0],
            thrust=[20000],
            phase_id=[0],
            phases=(),
            vehicle=sched.vehicle,
        )


def test_the_documented_example_and_error_are_what_the_code_does():
    doc = (SHIPPED_PLANS_DIR.parent / "docs" / "flightplans.md").read_text()
    example = doc.split("## Example", 1)[1].split("```toml\n", 1)[1].split("```", 1)[0]
    raw = tomllib.loads(example)
    expected = round(sum(p["duration"] for p in raw["phase"]) * raw["setpoint_rate_hz"])
    assert len(parse_plan(text=example).compile()) == expected
    documented = next(ln.strip() for ln in doc.splitlines() if "prbs-3axis.toml:" in ln)
    text = (SHIPPED_PLANS_DIR / "prbs-3axis.toml").read_text()
    with pytest.raises(PlanError) as info:
        parse_plan(
            text=text.replace("amplitude = 25.0 ", "amplitude = 35.0 ", 1),
            source="flightplans/prbs-3axis.toml",
        )
    assert str(info.value) == documented


@pytest.mark.parametrize(("extra", "expect"), [
    ("[parameters]\npid_attitude.yaw_kd = 0.0\nstabilizer.estimator = 2\n",
     (("pid_attitude.yaw_kd", 0.0), ("stabilizer.estimator", 2.0))),
    ("[parameters.pid_rate]\nyaw_kp = 100\n", (("pid_rate.yaw_kp", 100.0),)),
    ("", ()),
])
def test_parameters_are_read_in_file_order(extra, expect):
    assert parse_plan(text=BASE + "\n" + extra).parameters == expect


@pytest.mark.parametrize(("extra", "needle"), [
    ("[parameters]\nyaw_kd = 0.0\n", "'yaw_kd' is not a parameter group table"),
    ("[parameters]\npid.a.b = 1\n", "'pid.a' is not a firmware parameter name"),
    ('[parameters]\npid.kd = "0"\n', "'0' is not a number"),
    ("[parameters]\npid.kd = inf\n", "not a finite number"),
    ("[parameters]\npid.kd = true\n", "True is not a number"),
    ("[parameters]\n" + "".join(f"g.p{i} = 1\n" for i in range(33)), "33 parameters; at most 32"),
])
def test_bad_parameters_name_key_and_line(extra, needle):
    with pytest.raises(PlanError, match=re.escape(needle)) as err:
        parse_plan(text=BASE + "\n" + extra, source="p.toml")
    assert str(err.value).startswith("p.toml:") and "\n" not in str(err.value)


@pytest.mark.parametrize("body", [
    "pid = [1, 2]", 'pid = { kd = [0.1] }', "pid.kd = 1e400", 'pid.kd = 2024-01-01',
    '"pid attitude".kd = 1', 'pid."yaw kd" = 1', "pid.kd = { x = 1 }", "pid = 3",
    'pid.kd = "nan"', "[parameters.pid.inner]\nkd = 1",
])
def test_hostile_parameters_are_one_line_plan_errors(body):
    text = BASE + "\n[parameters]\n" + body + "\n"
    with pytest.raises(PlanError) as err:
        parse_plan(text=text, source="p.toml")
    assert "\n" not in str(err.value) and str(err.value).startswith("p.toml")
