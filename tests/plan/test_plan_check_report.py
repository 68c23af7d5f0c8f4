"""What ``plan check`` (and ``fly``) tell about a valid plan beyond its timeline: the altitude
hold and live identification it flies with, and warnings about plans that are valid but
probably not what was meant (longer than a battery, a ramp typed in ms, an amplitude typed in
rad); and the errors that say what to do (a PRBS typed in capitals, a negative PRBS amplitude,
an empty file)."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.errors import PlanError
from groundstation.plan import SHIPPED_PLANS_DIR, load_plan, parse_plan
from groundstation.plan.checks import plan_warnings

from .conftest import line_of


def _check(path, *args):
    return CliRunner().invoke(main, ["plan", "check", *args, str(path)])


def _shipped(name: str) -> str:
    return (SHIPPED_PLANS_DIR / f"{name}.toml").read_text(encoding="utf-8")


def test_check_shows_the_hover_height_and_live_id_settings(tmp_path):
    """A changed hover height could not be confirmed before flying (review): check showed
    neither [altitude_hold] nor [live_id]."""
    path = tmp_path / "p.toml"
    text = _shipped("prbs-3axis").replace("target_m = 1.0 ", "target_m = 1.5 ")
    path.write_text(text + "\n[live_id]\norder = 6\n", encoding="utf-8")
    res = _check(path)
    assert res.exit_code == 0, res.output
    hold = next(line for line in res.output.splitlines() if line.startswith("altitude hold"))
    assert "1.5 m on stateEstimate.z" in hold and "kp 4000" in hold
    assert "(defaults: kinds)" in hold  # the one key the plan leaves out
    live = next(line for line in res.output.splitlines() if line.startswith("live ident"))
    assert "order 6" in live and "past 60" in live and "defaults: future" in live
    summary = json.loads(_check(path, "--json").output)
    assert summary["altitude_hold"]["target_m"] == 1.5 and summary["altitude_hold"]["active"]
    assert summary["live_id"]["order"] == 6 and "order" not in summary["live_id"]["defaults"]
    # without the tables: no hold (thrust open loop), and the defaults --live-id would use
    bare = tmp_path / "bare.toml"
    start, end = text.index("[altitude_hold]"), text.index("[safety]")
    bare.write_text(text[:start] + text[end:], encoding="utf-8")
    res = _check(bare)
    assert "altitude hold: none (no [altitude_hold] table): thrust open loop" in res.output
    assert "fly --live-id would use the defaults: motors -> gyro, order 8" in res.output
    summary = json.loads(_check(bare, "--json").output)
    assert not summary["altitude_hold"]["active"] and not summary["live_id"]["active"]
    assert set(summary["live_id"]["defaults"]) == {"inputs", "outputs", "order", "past",
                                                   "future", "update_period"}


@pytest.mark.parametrize("name", sorted(p.stem for p in SHIPPED_PLANS_DIR.glob("*.toml")))
def test_the_shipped_plans_warn_of_nothing(name):
    assert plan_warnings(load_plan(name)) == []


def test_a_plan_longer_than_a_battery_warns_naming_its_longest_phase(tmp_path):
    """A 30-minute PRBS passed silently (review); a Crazyflie 2.x flies about 7 minutes."""
    text = _shipped("prbs-3axis").replace("duration = 102.3 ", "duration = 1818.3 ")
    path = tmp_path / "long.toml"
    path.write_text(text, encoding="utf-8")
    res = _check(path)
    assert res.exit_code == 0, res.output  # a warning, not a refusal
    warning = f"warning: {path}:{line_of(text, 'duration = 1818.3')}: phase[2].duration: "
    assert warning in res.output, res.output
    assert "flies 1828.3 s (30.5 min), longer than one battery lasts" in res.output
    assert "flight_time_s = 420 s, the default" in res.output
    # a vehicle with a bigger battery says so
    bigger = text.replace("min_vbat = 3.8 ", "flight_time_s = 2400\nmin_vbat = 3.8 ")
    assert plan_warnings(parse_plan(text=bigger, source="big.toml")) == []
    (w,) = plan_warnings(parse_plan(text=_shipped("prbs-3axis").replace(
        "min_vbat = 3.8 ", "flight_time_s = 60\nmin_vbat = 3.8 "), source="s.toml"))
    assert "flies 112.3 s" in w and "flight_time_s = 60 s)" in w and "the default" not in w


def test_a_ramp_typed_in_milliseconds_warns_with_the_value_in_seconds(tmp_path):
    text = _shipped("hover-check")
    slip = text.replace("\nduration = 2.0 ", "\nduration = 2000 ", 1)
    path = tmp_path / "slip.toml"
    path.write_text(slip, encoding="utf-8")
    res = _check(path, "--json")
    warnings = json.loads(res.output)["warnings"]
    ramp = [w for w in warnings if "take-off ramp" in w]
    assert len(ramp) == 1 and ramp[0].startswith(f"{path}:{line_of(slip, 'duration = 2000')}: "
                                                 "phase[0].duration: a take-off ramp of 2000 s")
    assert ramp[0].endswith("if it was meant in ms, write duration = 2")
    assert any("longer than one battery" in w for w in warnings)  # 33 minutes of it
    # a 20 s landing is slow, not a slip
    assert plan_warnings(parse_plan(text=text.replace("duration = 3.0 ", "duration = 20.0 "),
                                    source="slow.toml")) == []


def test_an_amplitude_typed_in_radians_warns(tmp_path):
    """amplitude = 0.2 # rad flies ±0.2 deg: below the limit in radians (30 deg = 0.52 rad), where
    every value meant in rad within the limit lands."""
    text = _shipped("roll-only").replace("amplitude = 25.0 ", "amplitude = 0.2 ", 1)
    (w,) = plan_warnings(parse_plan(text=text, source="rad.toml"))
    assert w.startswith(f"rad.toml:{line_of(text, 'amplitude = 0.2')}: phase[2].roll.amplitude: "
                        "±0.2 deg is below 0.524 deg")
    assert "0.2 rad = 11.5 deg" in w
    fine = text.replace("amplitude = 0.2 ", "amplitude = 0.6 ")
    assert plan_warnings(parse_plan(text=fine, source="ok.toml")) == []
    yaw = _shipped("yaw-only").replace("amplitude = 50.0 ", "amplitude = 0.87 ", 1)
    (w,) = plan_warnings(parse_plan(text=yaw, source="yaw.toml"))
    assert "phase[2].yaw_rate.amplitude: ±0.87 deg/s is below 3.49 deg/s" in w
    step = _shipped("yaw-only").replace("amplitude = 40.0 ", "amplitude = 0.7 ", 1)
    (w,) = plan_warnings(parse_plan(text=step, source="step.toml"))
    assert "yaw_rate.amplitude: 0.7 deg/s is below" in w  # a step goes one way: no ±


def test_fly_prints_the_plans_warnings_before_flying(tmp_path):
    plan = tmp_path / "rad.toml"
    plan.write_text(_shipped("hover-check").replace("duration = 3.0 ", "duration = 31.0 "),
                    encoding="utf-8")
    res = CliRunner().invoke(main, ["fly", str(plan), "--uri", "sim://0?speed=inf",
                                    "--out", str(tmp_path / "s"), "--json"])
    assert res.exit_code == 0, res.output
    assert "warning: " in res.stderr and "a landing ramp of 31 s" in res.stderr
    json.loads(res.stdout)  # the summary stays clean JSON


@pytest.mark.parametrize(("edit", "needle"), [
    (('signal = "prbs"', 'signal = "PRBS"'), "'PRBS' is not one of ['prbs', 'doublet', 'step', "
                                             "'chirp']; did you mean 'prbs', case matters?"),
    (('kind = "hover"', 'kind = "Hover"'), "did you mean 'hover', case matters?"),
    (("amplitude = 25.0 ", "amplitude = -12.0 "),
     "-12 deg must be > 0: a PRBS is symmetric (±amplitude); give the magnitude, "
     "amplitude = 12"),
    (("amplitude = 25.0 ", "amplitude = 0 "), "0 deg excites nothing"),
])
def test_errors_say_what_to_do(edit, needle):
    text = _shipped("pitch-only").replace(*edit, 1)
    with pytest.raises(PlanError) as err:
        parse_plan(text=text, source="p.toml")
    assert needle in str(err.value), str(err.value)
    assert str(err.value).startswith(f"p.toml:{line_of(text, edit[1].strip())}: ")


@pytest.mark.parametrize(("text", "what"), [("", "is empty"), ("\n  \n", "is empty"),
                                            ("# a plan\n\n# to come\n", "holds only comments")])
def test_an_empty_file_is_called_empty(tmp_path, text, what):
    """It said ``vehicle: missing required key 'vehicle'``, as if one table were forgotten."""
    path = tmp_path / "new.toml"
    path.write_text(text, encoding="utf-8")
    res = _check(path)
    assert res.exit_code == 2 and res.stderr.count("\n") == 1, res.output
    assert f"error: {path}: the file {what}" in res.stderr
    assert "hover-check.toml" in res.stderr and "missing required key" not in res.stderr


@pytest.mark.parametrize("name", sorted(p.stem for p in SHIPPED_PLANS_DIR.glob("*.toml")))
def test_the_shipped_plans_state_the_altitude_rate_a_flight_logs(name):
    """They said 'logged at the setpoint rate' (10 Hz); a flight logs it at twice that."""
    from groundstation.flight.liveid import planned_streams

    plan = load_plan(name)
    (altitude,) = [s for s in planned_streams(plan) if s.name == "altitude"]
    line = next(x for x in plan.text.splitlines() if x.startswith("variable = "))
    assert f"logged at {1 / altitude.period_s:g} Hz" in line


def test_the_prbs_table_relates_ticks_to_sysids_samples():
    """PE order in setpoint ticks beside sysid's horizons in log samples, nothing relating them
    (review): the note under the table says how many log samples a tick is."""
    res = CliRunner().invoke(main, ["plan", "check", "prbs-3axis"])
    assert res.exit_code == 0, res.output
    assert ("(period, clock and PE order in setpoint ticks of 0.1 s; sysid's past and future "
            "count log samples, 5 per tick at 50 Hz)") in " ".join(res.stdout.split())
