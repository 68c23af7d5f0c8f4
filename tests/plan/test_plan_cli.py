"""``groundstation plan check|show`` through the real command line (click's CliRunner)."""

from __future__ import annotations

import json
import re
import tomllib

import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.commands.plan import plot_lines
from groundstation.plan import SHIPPED_PLANS_DIR
from tests.plan.conftest import BASE, line_of


def _run(*args: str):
    return CliRunner().invoke(main, list(args))


@pytest.mark.parametrize("name", ["prbs-3axis", "hover-check", "yaw-only"])
def test_check_prints_timeline_duration_count_and_prbs_figures(name):
    raw = tomllib.loads((SHIPPED_PLANS_DIR / f"{name}.toml").read_text())
    duration = sum(p["duration"] for p in raw["phase"])
    n = round(duration * raw["setpoint_rate_hz"])
    result = _run("plan", "check", name)
    assert result.exit_code == 0, result.output
    out = result.output
    assert f"{n} setpoints at {raw['setpoint_rate_hz']:g} Hz, duration {duration:g} s" in out
    for p in raw["phase"]:
        assert p["name"] in out
    for p in raw["phase"]:
        for axis, sig in p.items():
            if isinstance(sig, dict) and sig.get("signal") == "prbs":
                period = 2 ** sig["register_length"] - 1  # clock period 1: PE order = period
                row = f"{p['name']}/{axis}"
                line = next(ln for ln in out.splitlines() if ln.startswith(row))
                assert f"{period} = {period / raw['setpoint_rate_hz']:g} s" in line
                assert line.split()[-2:] == [str(period), "1.00"]


def test_check_json_reports_persistence_order_and_lags():
    result = _run("plan", "check", "prbs-3axis", "--json")
    assert result.exit_code == 0
    summary = json.loads(result.output)
    assert [f["axis"] for f in summary["prbs"]] == ["roll", "pitch", "yaw_rate"]
    for f in summary["prbs"]:
        assert f["period_ticks"] == f["pe_order_ticks"] == 1023 and f["clock_period_ticks"] == 1
    assert summary["prbs"][0]["lag_ticks"] == {"pitch": 341, "yaw_rate": 341}
    assert summary["warnings"] == []


def test_check_warns_when_prbs_seeds_are_close(tmp_path):
    close = BASE.replace(
        '[phase.yaw_rate]\nsignal = "doublet"',
        '[phase.yaw_rate]\nsignal = "prbs"\nregister_length = 5\nseed = 6\n#',
    ).replace("width = 0.5", "")
    close = close.replace("start = 0.2", "")
    path = tmp_path / "close.toml"
    path.write_text(close)
    result = _run("plan", "check", str(path))
    assert result.exit_code == 0, result.output
    assert "warning:" in result.output and "roll and yaw_rate PRBS" in result.output


@pytest.mark.parametrize(
    ("old", "new", "needle", "key"),
    [
        ("amplitude = 20.0", "amplitude = 45.0", "amplitude = 45.0", "phase[1].roll.amplitude"),
        ("duration = 3.1", "duration = 3.1.2", "duration = 3.1.2", "invalid TOML"),
        ("seed = 3", "sed = 3", "sed = 3", "phase[1].roll.sed"),
    ],
)
def test_bad_plan_exits_2_with_one_line_naming_key_and_line(tmp_path, old, new, needle, key):
    path = tmp_path / "bad.toml"
    text = BASE.replace(old, new)
    path.write_text(text)
    for sub in ("check", "show"):
        result = _run("plan", sub, str(path))
        assert result.exit_code == 2
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"error: {path}:{line_of(text, needle)}: ")
        assert key in lines[0] and "Traceback" not in result.output


def test_missing_plan_exits_2():
    result = _run("plan", "check", "no-such-plan")
    assert result.exit_code == 2 and "prbs-3axis" in result.stderr
    assert "did you mean" not in result.stderr  # nothing close


@pytest.mark.parametrize(("args", "hint"), [
    (["plan", "check", "prbs3axis"], "no such plan file; did you mean 'prbs-3axis'?"),
    (["fly", "hover-chek", "--uri", "sim://0"], "did you mean 'hover-check'?"),
])
def test_a_mistyped_plan_name_is_named(args, hint):
    result = _run(*args)
    assert result.exit_code == 2 and hint in result.stderr, result.output


def test_a_mistyped_choice_is_named(tmp_path):
    path = tmp_path / "bad.toml"
    text = BASE.replace('kind = "landing"', 'kind = "landng"', 1)
    assert text != BASE
    path.write_text(text)
    result = _run("plan", "check", str(path))
    assert result.exit_code == 2
    assert result.stderr.strip().endswith("'landng' is not one of ['takeoff', 'hover', "
                                          "'excitation', 'landing']; did you mean 'landing'?")


def test_show_json_dumps_the_schedule():
    result = _run("plan", "show", "hover-check", "--json")
    assert result.exit_code == 0
    d = json.loads(result.output)
    sp = d["setpoints"]
    assert d["n_setpoints"] == len(sp["t"]) == 100 and d["units"]["thrust"] == "PWM"
    assert sp["t"][10] == 1.0 and sp["thrust"][0] == 20000 and sp["thrust"][19] == 42000
    assert [p["name"] for p in d["phases"]] == ["takeoff", "hover", "land"]


def test_show_draws_every_axis_and_phase():
    result = _run("plan", "show", "pitch-only", "--width", "60", "--height", "4")
    assert result.exit_code == 0, result.output
    out = result.output
    for axis in ("roll [deg]", "pitch [deg]", "yaw_rate [deg/s]", "thrust [PWM]"):
        assert axis in out
    pitch_rows = out.split("pitch [deg]")[1].splitlines()[1:5]
    assert pitch_rows[0].strip().startswith("25") and pitch_rows[3].strip().startswith("-25")
    assert "2: 5-30.5 s prbs (excitation)" in out


def test_plot_lines_draws_a_ramp_as_a_diagonal_and_a_prbs_as_a_band():
    ramp = plot_lines(np.arange(4.0), width=4, height=4)
    assert ramp == ["   █", "  █ ", " █  ", "█   "]
    band = plot_lines(np.tile([-1.0, 1.0], 20), width=5, height=3)
    assert band == ["█████"] * 3
    coarse = plot_lines(np.arange(40.0), width=4, height=4)  # each column spans its min..max
    assert coarse == ["   █", "  ██", "██  ", "█   "]


CONTROL = re.compile("[\x00-\x09\x0b-\x1f\x7f-\x9f\u202e]")  # every control but line feed
HOSTILE_NAME = "ex\x1b[2Jcite\r\x07\u202e"
"""A phase name that clears the screen, rewrites the line, rings the bell and reverses what
follows, printed raw by ``plan check``/``show`` before (review)."""


@pytest.mark.parametrize("args", [("check",), ("show", "--width", "40")])
def test_control_characters_of_a_plan_are_shown_escaped(tmp_path, args):
    path = tmp_path / "hostile.toml"
    # TOML takes control characters as escapes only; the PRBS covers less than its period, so
    # the name is in the table, the PRBS table and the warning
    path.write_text(BASE.replace('name = "excite"', f"name = {json.dumps(HOSTILE_NAME)}")
                    .replace("register_length = 5", "register_length = 6"))
    result = _run("plan", *args, str(path))
    assert result.exit_code == 0, result.output
    assert not CONTROL.search(result.output), repr(result.output)
    shown = r"ex\x1b[2Jcite\r\x07\u202e"
    assert shown in result.output
    if args[0] == "check":
        assert f"{shown}/roll" in result.output and f"warning: phase {shown} roll" in \
            result.output


def test_an_error_naming_a_hostile_path_is_escaped(tmp_path):
    """The one error line quotes the path as given: its control characters escaped."""
    result = _run("plan", "check", str(tmp_path / "no\x1b[2Jplan.toml"))
    assert result.exit_code == 2
    assert "\x1b" not in result.output and r"no\x1b[2Jplan" in result.output
