"""cfsession.channels: the one rule turning channel names into log variables, shared by offline
identification (sysid, on a session as read) and live identification (on the flight's specs).
Each case of the rule, its labels, its one-line errors, and the same answer on the specs a
flight writes and on the session read back."""

from __future__ import annotations

import dataclasses

import pytest

from cfsession import (
    Channel,
    ChannelError,
    SessionError,
    SessionWriter,
    open_session,
    resolve_channels,
    standard_streams,
)
from cfsession.channels import session_specs
from cfsession.schema import log_block_spec, setpoints_spec

PERIOD = 0.02


def _specs():
    def block(name, variables):
        return log_block_spec(name=name, variables=[(v, "float") for v in variables],
                              period_s=PERIOD)

    return [block("motors", [f"motor.m{i}" for i in range(1, 5)]),
            block("gyro", ["gyro.x", "gyro.y", "gyro.z"]),
            block("imu", ["acc.x", "acc.y"]),  # the group 'acc' has no stream of its name
            block("ctrl", ["controller.cmd_roll", "controller.r_roll"]),
            block("ctrl_fast", ["controller.cmd_roll"]),  # logged in two streams
            block("b_att", ["roll.b"]), block("a_att", ["roll.a"]),  # a group over two streams
            setpoints_spec()]


SPECS = _specs()


def labels(names, *, streams=SPECS, role="output"):
    return [c.label for c in resolve_channels(names, streams=streams, role=role)]


def test_a_stream_name_selects_its_fields_in_order_labelled_by_variable():
    chans = resolve_channels(["motors"], streams=SPECS, role="input")
    assert chans[0] == Channel("motors", "m1", "motor.m1", "PWM (0-65535)")
    assert [c.label for c in chans] == ["motor.m1", "motor.m2", "motor.m3", "motor.m4"]


def test_stream_dot_field_and_firmware_variable_select_one_field_each():
    chans = resolve_channels(["motors.m2", "motor.m4", "gyro.z"], streams=SPECS, role="input")
    assert [(c.stream, c.field, c.label) for c in chans] == [
        ("motors", "m2", "motor.m2"), ("motors", "m4", "motor.m4"), ("gyro", "z", "gyro.z")]
    assert [c.unit for c in chans] == ["PWM (0-65535)"] * 2 + ["deg/s"]
    assert labels(["controller.r_roll"]) == ["controller.r_roll"]  # unique: its variable name


def test_a_variable_group_selects_every_logged_variable_of_the_group():
    assert labels(["acc"]) == ["acc.x", "acc.y"]  # no stream 'acc': the group
    assert labels(["motor"]) == ["motor.m1", "motor.m2", "motor.m3", "motor.m4"]
    assert labels(["gyro"]) == ["gyro.x", "gyro.y", "gyro.z"]  # the stream, same variables
    # a variable logged twice is labelled by stream.field, so the group still works
    assert labels(["controller"]) == ["ctrl.cmd_roll", "ctrl_fast.cmd_roll", "controller.r_roll"]
    assert labels(["roll"]) == ["roll.a", "roll.b"]  # streams by name, whatever their order


def test_a_variable_logged_in_several_streams_must_be_named_by_stream():
    with pytest.raises(ChannelError) as err:
        resolve_channels(["controller.cmd_roll"], streams=SPECS, role="input")
    msg = str(err.value)
    assert err.value.problem == "ambiguous" and "\n" not in msg
    assert "input 'controller.cmd_roll' is logged in several streams" in msg
    assert "ctrl.cmd_roll" in msg and "ctrl_fast.cmd_roll" in msg
    assert labels(["ctrl_fast.cmd_roll"]) == ["ctrl_fast.cmd_roll"]


@pytest.mark.parametrize("names", [["motors", "motor.m1"], ["gyro.x", "gyro"],
                                   ["imu.x", "acc.x"]])
def test_a_channel_selected_twice_is_refused(names):
    with pytest.raises(ChannelError, match=r"input channel\(s\) \[.*\] selected twice") as err:
        resolve_channels(names, streams=SPECS, role="input")
    assert err.value.problem == "duplicate" and err.value.role == "input"


@pytest.mark.parametrize("name", ["baro", "gyro.w", "setpoints", "setpoints.roll", "motor.m9",
                                  "host_time", "gyro.fw_time_ms", ""])
def test_an_unknown_name_names_itself_the_role_and_the_log_streams(name):
    with pytest.raises(ChannelError) as err:
        resolve_channels(["gyro", name], streams=SPECS, role="output")
    exc, msg = err.value, str(err.value)
    assert (exc.problem, exc.name, exc.role) == ("unknown", name, "output")
    logged = ("a_att", "b_att", "ctrl", "ctrl_fast", "gyro", "imu", "motors")  # log streams only
    assert exc.logged == logged
    assert f"no log stream or variable {name!r} for the outputs" in msg and "\n" not in msg
    assert f"log streams are {list(logged)} holding variables " in msg
    assert "'gyro.x', " in msg and " in all) (use STREAM" in msg  # the firmware's names too
    assert isinstance(exc, SessionError) and isinstance(exc, ValueError)  # printed as one line


@pytest.mark.parametrize(("name", "meant"), [("Motors", "'motors'"), ("GYRO.X", "'gyro.x'"),
                                              ("motrs", "'motors'"), ("baro", None)])
def test_a_misspelt_name_gets_the_names_it_was_close_to(name, meant):
    with pytest.raises(ChannelError) as err:
        resolve_channels([name], streams=SPECS, role="input")
    msg = str(err.value)
    if meant is None:
        assert "did you mean" not in msg, msg
    else:
        assert f"for the inputs (did you mean {meant}?)" in msg, msg


def test_no_names_select_nothing_and_are_refused():
    with pytest.raises(ChannelError, match="no input channels selected") as err:
        resolve_channels([], streams=SPECS, role="input")
    assert err.value.problem == "empty"


def test_a_session_read_back_resolves_as_the_specs_it_was_written_with(tmp_path):
    empty = log_block_spec(name="baro", variables=[("baro.asl", "float")], period_s=PERIOD)
    path = tmp_path / "s.h5"
    with SessionWriter(path, streams=[*SPECS[:-1], empty, *standard_streams()]) as w:
        for spec in SPECS[:-1]:
            w.append(spec.name, (0.0, 0, *[1.0] * (len(spec.fields) - 2)))
    specs = session_specs(open_session(path))
    assert sorted(s.name for s in specs) == sorted(s.name for s in SPECS[:-1])  # no 'baro'
    for names in (["motors", "imu"], ["gyro.z", "motor.m1"], ["controller"], ["acc"],
                  ["roll"]):
        assert (resolve_channels(names, streams=specs, role="input")
                == resolve_channels(names, streams=SPECS, role="input")), names
    with pytest.raises(ChannelError, match=r"'baro\.asl'"):  # no rows: nothing to select
        resolve_channels(["baro.asl"], streams=specs, role="input")


@pytest.mark.parametrize("names", [["gyro.y"], ["gyro"], ["motor.m1", "gyro"]])
def test_a_field_of_text_is_no_channel(names):
    """A session file may hold a text field in a log stream (the reader takes numbers and
    fixed-length text); selected as a channel it made sysid raise ValueError (could not
    convert string to float) with a traceback."""
    gyro = log_block_spec(name="gyro", variables=[("gyro.x", "float"), ("gyro.y", "float")],
                          period_s=PERIOD)
    fields = tuple(dataclasses.replace(f, dtype="S4") if f.name == "y" else f
                   for f in gyro.fields)
    streams = [SPECS[0], dataclasses.replace(gyro, fields=fields)]
    with pytest.raises(ChannelError, match=r"output 'gyro\.y' \(field 'y' of log stream "
                                           r"'gyro'\) holds text \(\|S4\), not numbers") as err:
        resolve_channels(names, streams=streams, role="output")
    assert err.value.problem == "text" and "\n" not in str(err.value)
    assert labels(["gyro.x"], streams=streams) == ["gyro.x"]  # its numbers still select
