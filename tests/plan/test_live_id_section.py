"""The plan's ``[live_id]`` table: defaults without knobs, values read, every mistake one line
naming key and line (``plan check`` through the command line too), and the channel names
checked against the log blocks a flight of the plan records."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.errors import PlanError
from groundstation.flight.liveid import check_live_id, planned_streams
from groundstation.plan import LiveIdConfig, load_plan, parse_plan

from .conftest import line_of


def _with(base: str, table: str) -> str:
    return f"{base}\n[live_id]\n{table}\n"


def test_no_table_means_no_live_id_and_an_empty_table_the_documented_defaults(base_text):
    assert parse_plan(text=base_text).live_id is None
    cfg = parse_plan(text=_with(base_text, "")).live_id
    assert cfg == LiveIdConfig()
    assert (cfg.inputs, cfg.outputs, cfg.order, cfg.past, cfg.future, cfg.update_period) == (
        ("motors",), ("gyro",), 8, 60, 17, 1.0)


def test_values_are_read(base_text):
    cfg = parse_plan(text=_with(base_text, 'inputs = ["motor.m1", "motor.m2"]\n'
                                           'outputs = ["gyro.x", "gyro.z"]\norder = 4\n'
                                           "past = 20\nfuture = 10\nupdate_period = 0.5")).live_id
    assert cfg == LiveIdConfig(inputs=("motor.m1", "motor.m2"), outputs=("gyro.x", "gyro.z"),
                               order=4, past=20, future=10, update_period=0.5)


@pytest.mark.parametrize(("table", "key", "needle"), [
    ('outputs = "gyro"', "outputs", "non-empty array of channel names"),
    ("outputs = []", "outputs", "non-empty array of channel names"),
    ('outputs = ["gyro x"]', "outputs", "is not a channel name"),
    ('outputs = ["gyro.x", "gyro.x"]', "outputs", "named twice"),
    ('inputs = ["gyro"]', "live_id", "both an input and an output"),
    # a whole stream holds its fields: plan check passed this, fly refused it (audit)
    ('outputs = ["motors.m1"]\ninputs = ["motors"]', "outputs", "both an input and an output"),
    ('inputs = ["gyro.x"]', "live_id", "both an input and an output"),
    ("order = 0", "order", "out of range"),
    ("order = 4.5", "order", "is not an integer"),
    # the unit in brackets: it read "True is not an integer in states"
    ("order = true", "order", "True is not an integer (states)"),
    ("past = 0", "past", "out of range"),
    ("future = 1", "future", "out of range"),
    ("update_period = 0", "update_period", "out of range"),
    ("update_period = nan", "update_period", "not a finite number"),
    ('outputs = ["gyro.x"]\norder = 20', "order", "exceeds (future - 1) x 1 outputs"),
    ("horizon = 3", "horizon", "unknown key 'horizon'"),
])
def test_mistakes_are_one_line_naming_key_and_line(base_text, table, key, needle):
    text = _with(base_text, table)
    with pytest.raises(PlanError) as err:
        parse_plan(text=text, source="p.toml")
    msg = str(err.value)
    assert "\n" not in msg and needle in msg, msg
    first = table.splitlines()[-1 if key == "order" else 0].split("=")[0].strip()
    line = line_of(text, "[live_id]") if key == "live_id" else line_of(text, first)
    assert msg.startswith(f"p.toml:{line}: live_id"), msg


def test_plan_check_refuses_a_bad_table_in_one_line(tmp_path, base_text):
    path = tmp_path / "p.toml"
    path.write_text(_with(base_text, "past = -3"), encoding="utf-8")
    res = CliRunner().invoke(main, ["plan", "check", str(path)])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "live_id.past" in res.output and "out of range" in res.output
    path.write_text(_with(base_text, "order = 6\npast = 10\nfuture = 5"), encoding="utf-8")
    assert CliRunner().invoke(main, ["plan", "check", str(path)]).exit_code == 0


def test_plan_check_refuses_a_live_id_the_excitation_is_too_short_for(tmp_path, base_text):
    """past = future = 400 over a 102 s excitation passed ``plan check`` and flew with no
    update and no reason; the names were checked against the log blocks by ``fly`` only."""
    path = tmp_path / "p.toml"
    # 3.1 s of excitation at 50 Hz: 155 samples; 7 channels, past + future = 20: 20 x 8 - 1
    path.write_text(_with(base_text, "past = 12\nfuture = 8"), encoding="utf-8")
    res = CliRunner().invoke(main, ["plan", "check", str(path)])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "need 159 samples (3.2 s) of excitation" in res.output
    assert "excites for 3.1 s (155 samples at 50 Hz)" in res.output
    path.write_text(_with(base_text, 'past = 10\nfuture = 5\ninputs = ["motor.m9"]'),
                    encoding="utf-8")
    res = CliRunner().invoke(main, ["plan", "check", str(path)])
    assert res.exit_code == 2 and "'motor.m9': no such log stream" in res.output, res.output


def test_fly_refuses_live_id_on_a_plan_without_excitation(tmp_path):
    res = CliRunner().invoke(main, ["fly", "hover-check", "--live-id", "--uri", "sim://0",
                                    "--out", str(tmp_path)])
    assert res.exit_code == 2 and "no excitation phase to identify from" in res.output
    assert list(tmp_path.iterdir()) == []  # refused before anything connected or was written


def test_channel_names_resolve_against_the_flight_log_blocks(base_text):
    plan = load_plan("prbs-3axis")  # with an altitude hold: the altitude block is logged too
    streams = planned_streams(plan)
    ins, outs, dt = check_live_id(LiveIdConfig(), streams=streams)
    assert [c.label for c in ins] == ["motor.m1", "motor.m2", "motor.m3", "motor.m4"]
    assert [c.label for c in outs] == ["gyro.x", "gyro.y", "gyro.z"] and dt == 0.02
    # stream.field, a logged variable and a variable group select the same channels
    for names in (("gyro.z", "acc.z"), ("stabilizer.roll",)):
        cfg = LiveIdConfig(outputs=names, order=2)
        if names[0].startswith("stabilizer"):  # 10 Hz attitude with 50 Hz motors: refused
            with pytest.raises(PlanError, match="different rates"):
                check_live_id(cfg, streams=streams)
        else:
            assert [c.label for c in check_live_id(cfg, streams=streams)[1]] == list(names)
    bad = [(LiveIdConfig(outputs=("gyr",)), "'gyr': no such log stream or variable"),
           (LiveIdConfig(inputs=("motors", "motor.m1")), "selected twice"),
           (LiveIdConfig(outputs=("gyro.z",), order=20), "exceeds the rank available")]
    for cfg, needle in bad:
        with pytest.raises(PlanError) as err:
            check_live_id(cfg, streams=streams)
        assert needle in str(err.value) and "\n" not in str(err.value), str(err.value)
    hover = parse_plan(text=base_text)  # no altitude hold: no altitude block to select
    with pytest.raises(PlanError, match="'altitude'"):
        check_live_id(LiveIdConfig(outputs=("altitude",)), streams=planned_streams(hover))


@pytest.mark.parametrize(("table", "key", "needle"), [
    ("order = 80", "order", "order 80 exceeds the rank available"),
    ('outputs = ["gyr"]', "outputs", "'gyr': no such log stream or variable"),
    ('outputs = ["stabilizer.roll"]\norder = 2', "outputs", "logged at different rates"),
    ('inputs = ["motors", "motor.m1"]', "inputs", "selected twice"),
    ("past = 600", "past", "of excitation for the first update"),
])
def test_the_flights_checks_of_a_live_id_table_name_its_key_and_line(tmp_path, table, key,
                                                                      needle):
    """fly's checks against the log blocks and the excitation's length (which plan check runs)
    said ``live_id: ...`` where the loader's own said ``FILE:LINE: live_id.KEY``: a user could
    not tell which line of the table to change (review)."""
    path = tmp_path / "p.toml"
    text = _with(load_plan("pitch-only").text, table)  # 25.5 s of PRBS: too short for past 600
    path.write_text(text, encoding="utf-8")
    res = CliRunner().invoke(main, ["plan", "check", str(path)])
    assert res.exit_code == 2 and res.stderr.count("\n") == 1, res.output
    line = line_of(text, table.splitlines()[0])  # the key named first in the table
    assert res.stderr.startswith(f"error: {path}:{line}: live_id.{key}: "), res.stderr
    assert needle in res.stderr
    # --live-id on a plan without the table flies the defaults: no key or line to name
    with pytest.raises(PlanError, match=r"^live_id: output 'gyr': no such log stream"):
        check_live_id(LiveIdConfig(outputs=("gyr",)), streams=planned_streams(load_plan(
            "hover-check")))
