"""User mistakes and odd inputs around ``groundstation fly`` (and its siblings ``demo``, ``sim``,
``scan``): one line, exit 2, no traceback, nothing connected or written over; and the runner
never sends a setpoint that is not a finite number."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from click.testing import CliRunner

import groundstation.flight.runner as flight_mod
import groundstation.recorder as recorder_mod
import groundstation.sim as gsim
from cfsession import open_session, standard_streams
from groundstation.cli import main
from groundstation.commands.fly import command as fly_command
from groundstation.errors import LinkError, PlanError, SessionError
from groundstation.flight import fly_plan
from groundstation.plan import MAX_RATE_RANGE_DEG_S, find_plan, load_plan, parse_plan
from groundstation.plan.schedule import Schedule
from groundstation.recorder import Recorder, session_path

from .checks import check_closed_with_stop
from .conftest import SITL_HOST_SIDE, backends, wait_for_stop


def one_line_error(res, *, code: int = 2) -> str:
    """Exit ``code``, no traceback, exactly one error line; returns that line."""
    assert res.exit_code == code, res.output
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    errors = [ln for ln in res.output.splitlines() if ln.lower().startswith("error")]
    assert len(errors) == 1, res.output
    return errors[0]


def never_connected(uri: str) -> bool:
    try:
        gsim.instance(uri)
    except LinkError:
        return True
    return False


# ------------------------------------------------------------------ non-finite numbers
@pytest.mark.parametrize("args", [["--max-rate", "nan"], ["--max-rate", "inf"],
                                  ["--timeout", "nan"], ["--timeout", "inf"]])
def test_fly_refuses_non_finite_options(args, sim_uri, tmp_path):
    uri = sim_uri()
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out",
                                    str(tmp_path / "s"), *args])
    assert "finite" in one_line_error(res)
    assert never_connected(uri) and not (tmp_path / "s").exists()


@pytest.mark.parametrize(("value", "words"), [("1e9", "above 5000"), ("6000", "above 5000"),
                                            ("5", "below 10"), ("9.99", "below 10")])
def test_fly_max_rate_has_the_plan_keys_range(value, words, sim_uri, tmp_path):
    """--max-rate 1e9 flew with the gyro-rate abort off in effect, while the plan key
    safety.max_rate_deg_s refuses anything outside 10..5000 deg/s: one range for both."""
    uri = sim_uri()
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out",
                                    str(tmp_path / "s"), "--max-rate", value])
    line = one_line_error(res)
    assert "--max-rate" in line and words in line, line
    assert never_connected(uri) and not (tmp_path / "s").exists()


def test_fly_max_rate_range_is_the_plan_keys_and_help_says_it():
    lo, hi = MAX_RATE_RANGE_DEG_S
    option = next(p for p in fly_command.params if p.name == "max_rate")
    assert (option.type.min, option.type.max) == (lo, hi) == (10.0, 5000.0)
    text = find_plan("hover-check").read_text()
    for value, ok in ((lo, True), (hi, True), (hi + 1, False), (lo - 0.5, False)):
        edited = text.replace("[safety]\n", f"[safety]\nmax_rate_deg_s = {value!r}\n", 1)
        if ok:
            assert parse_plan(text=edited).compile().safety.max_rate_deg_s == value
        else:
            with pytest.raises(PlanError, match="max_rate_deg_s"):
                parse_plan(text=edited)
    res = CliRunner().invoke(main, ["fly", "--help"])
    assert "FLOAT >=10 <=5000" in res.output and "(10 to 5000, as the plan's" in " ".join(
        res.output.split()), res.output


def test_fly_speed_says_where_the_speed_goes(sim_uri, tmp_path):
    # click suggested --seed, which changes the PRBS, not the simulation's speed
    uri = sim_uri()
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--speed", "10",
                                    "--out", str(tmp_path / "s")])
    line = one_line_error(res)
    assert "sim://0?speed=20" in line and "--seed" not in line
    assert never_connected(uri) and not (tmp_path / "s").exists()


@pytest.mark.parametrize("cmd", [["demo", "--speed", "nan"], ["demo", "--speed", "-inf"],
                                 ["sim", "--duration", "nan"], ["sim", "--duration", "inf"]])
def test_other_float_options_refuse_non_finite(cmd):
    # demo --speed inf is flat out in lock-step (tests/demo); -inf and nan stay refused
    assert "finite" in one_line_error(CliRunner().invoke(main, cmd))


@backends(sitl=SITL_HOST_SIDE)
def test_non_finite_setpoint_aborts_through_the_abort_path(flight_uri, tmp_path, monkeypatch):
    """A NaN reaching the runner is never sent: abort, plan's descent, stop, file kept."""
    setpoint = Schedule.setpoint

    def poisoned(self, k):
        sp = setpoint(self, k)
        return (math.nan, *sp[1:]) if k == 40 and not self.name.endswith(":abort") else sp

    monkeypatch.setattr(Schedule, "setpoint", poisoned)
    uri = flight_uri()
    result = fly_plan(plan=load_plan("hover-check"), out=tmp_path, uri=uri)
    assert result.aborted and "setpoint 40" in result.cause and "not finite" in result.cause
    wait_for_stop(uri)  # motors off (sitl: the firmware's motor commands are zero)
    s = check_closed_with_stop(result)
    sp = s["setpoints"].data
    assert all(np.isfinite(sp[c]).all() for c in ("roll", "pitch", "yaw_rate"))
    assert sp["tick"].max() == 39
    abort = sp[(sp["tick"] == -1) & (sp["thrust"] > 0)]
    assert len(abort) == 20 and (abort["thrust"] <= 34000).all()  # the plan's descent
    assert any("not finite" in e.text and e.source == "safety" for e in s.events())


# ------------------------------------------------------------------ output folder and file name
def test_fly_out_is_a_file_fails_before_connecting(sim_uri, tmp_path):
    uri, out = sim_uri(), tmp_path / "taken"
    out.write_text("keep me")
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out", str(out)])
    line = one_line_error(res)
    assert "--out" in line and str(out) in line
    assert never_connected(uri) and out.read_text() == "keep me"


def test_fly_out_naming_a_session_file_fails_before_connecting(sim_uri, tmp_path):
    """`--out flight.h5` (as `sysid identify --out model.h5`) made a folder named flight.h5
    holding hover-check-TIME.h5, which `groundstation info flight.h5` then refused as a
    folder; demo and import share the check."""
    uri, out = sim_uri(), tmp_path / "sub" / "flight.h5"
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out", str(out)])
    line = one_line_error(res)
    assert f"--out {out}: names a session file" in line and f"--out {out.parent}" in line
    assert never_connected(uri) and not (tmp_path / "sub").exists()
    (tmp_path / "kept.h5").mkdir()  # a folder of that name that exists is a folder
    assert recorder_mod.check_folder(tmp_path / "kept.h5") == tmp_path / "kept.h5"


def test_fly_out_that_cannot_be_created_fails_before_connecting(sim_uri, tmp_path):
    uri = sim_uri()
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out", "/proc/gs-x"])
    assert "cannot create folder /proc/gs-x" in one_line_error(res)
    assert never_connected(uri)


def test_over_long_file_name_is_one_line_before_connecting(sim_uri, tmp_path):
    with pytest.raises(SessionError, match="file name too long") as err:
        session_path(out=tmp_path, plan_name="x" * 300)
    assert "\n" not in str(err.value)
    plan = copy.copy(load_plan("hover-check"))
    object.__setattr__(plan, "name", "y" * 300)
    uri = sim_uri()
    with pytest.raises(SessionError, match="file name too long"):
        fly_plan(plan=plan, out=tmp_path, uri=uri)
    assert never_connected(uri) and not list(tmp_path.iterdir())


def test_recorder_create_error_is_one_line_and_nothing_flies(sim_uri, tmp_path, monkeypatch):
    """The file cannot be created after connecting (say the folder went away): one line,
    nothing flown, no traceback logged."""
    def refuse(path, *a, **kw):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(recorder_mod, "SessionWriter", refuse)
    uri = sim_uri()
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out", str(tmp_path)])
    line = one_line_error(res)
    assert "Permission denied" in line and "nothing flown" in line
    assert not list(tmp_path.iterdir())  # placeholder and temporary file removed
    assert gsim.instance(uri).vehicle.stop_count == 0 or not any(gsim.instance(uri)
                                                                 .vehicle.motors_pwm)


def _streams():
    return standard_streams()


def test_recorder_claims_the_name_when_it_creates_the_file(tmp_path):
    path = session_path(out=tmp_path, plan_name="p")
    path.write_bytes(b"another flight")  # taken meanwhile (another fly in the same second)
    first, second = Recorder(path, unique=True), Recorder(path, unique=True)
    first.begin(streams=_streams(), metadata={})
    second.begin(streams=_streams(), metadata={})
    assert path.read_bytes() == b"another flight"
    assert first.path.name == f"{path.stem}-2.h5" and second.path.name == f"{path.stem}-3.h5"
    first.end(summary={"duration_s": 0.0})
    second.end(summary={"duration_s": 0.0})
    assert open_session(first.path).closed_cleanly and open_session(second.path).closed_cleanly
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [path.name, first.path.name, second.path.name])  # no temporary files left
    with pytest.raises(SessionError, match="already exists"):
        Recorder(path).begin(streams=_streams(), metadata={})
    assert path.read_bytes() == b"another flight"


def test_two_flights_into_one_folder_in_the_same_second(sim_uri, tmp_path, monkeypatch):
    """The name the first choice found free is taken while connecting: the flight records to
    ``-2`` and flies; the other file is untouched."""
    taken = []

    def racing_session_path(**kw):
        path = session_path(**kw)
        path.write_bytes(b"the other flight")
        taken.append(path)
        return path

    monkeypatch.setattr(flight_mod, "session_path", racing_session_path)
    uri = sim_uri()
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out", str(tmp_path),
                                    "--json"])
    assert res.exit_code == 0, res.output
    assert "Traceback" not in res.output
    wait_for_stop(uri)
    assert taken[0].read_bytes() == b"the other flight"
    file = res.output[res.output.index("{"):]
    assert f"{taken[0].stem}-2.h5" in file
    assert open_session(tmp_path / f"{taken[0].stem}-2.h5").closed_cleanly


# ------------------------------------------------------------------ links
def test_unknown_uri_scheme_names_the_supported_ones(tmp_path):
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", "foo://0", "--out",
                                    str(tmp_path / "s")])
    line = one_line_error(res)
    assert "unknown link URI scheme" in line and "Crazyflie is on" not in line
    assert all(s in line for s in ("radio://", "usb://", "udp://", "sim://"))
    assert not (tmp_path / "s").exists()


def test_sim_speed_is_capped(tmp_path):
    uri = "sim://777?speed=1e9"
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out", str(tmp_path)])
    line = one_line_error(res)
    assert "speed" in line and "100" in line
    assert gsim.parse_uri("sim://0?speed=inf").speed == math.inf  # flat out stays available
    assert gsim.parse_uri("sim://0?speed=40").speed == 40


@pytest.mark.parametrize("address", ["-1", "E7E7E7E7E7E7E7", "0x", "zz", ""])
def test_scan_refuses_bad_radio_addresses(address):
    assert "--address" in one_line_error(CliRunner().invoke(main, ["scan", "--address",
                                                                   address]))


def test_scan_accepts_radio_addresses():
    from groundstation.commands.scan import _radio_address

    assert _radio_address("E7E7E7E7E7") == 0xE7E7E7E7E7 and _radio_address("0x1") == 1


# ------------------------------------------------------------------ demo
def test_demo_out_existing_file_is_one_line(tmp_path):
    out = tmp_path / "file"
    out.write_text("keep me")
    line = one_line_error(CliRunner().invoke(main, ["demo", "--out", str(out)]))
    assert "--out" in line and out.read_text() == "keep me"


def test_a_recorder_that_raises_aborts_and_says_what_the_file_lacks(sim_uri, tmp_path,
                                                                     monkeypatch):
    """The recorder raised once mid-flight: the flight aborted and the stop reached the vehicle,
    but the file (closed cleanly) ended at the failure without the stop row, and the result
    said only "session saved to" (safety review). The cause now says what the file holds."""
    real, calls = Recorder.rows, []

    def failing(self, stream, rows):
        calls.append(stream)
        if len(calls) == 200:
            raise RuntimeError("injected write failure")
        return real(self, stream, rows)

    monkeypatch.setattr(Recorder, "rows", failing)
    uri = sim_uri()
    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri)
    wait_for_stop(uri)
    assert result.aborted and result.cause.startswith("recording failed: "), result.cause
    assert "injected write failure" in result.cause
    lost = float(result.cause.split("up to about ")[1].split(" s only")[0])
    assert result.cause.endswith("s only, not its stop: recording failed then")
    s = open_session(result.path)
    t = s["setpoints"].data["host_time"] - s["setpoints"].data["host_time"][0]
    assert lost > 0 and t[-1] <= lost + 0.2  # the file does end about there


@pytest.mark.parametrize("target", ["setpoint_summary", "link.close"])
def test_a_step_after_the_stop_that_raises_keeps_the_stop_and_the_files_end(target, sim_uri,
                                                                            tmp_path,
                                                                            monkeypatch):
    """The steps after the stop ran unguarded: one that raised (the summary, closing the link)
    skipped the rest, and the file lost its stop row, its last rows and its clean close
    (safety review, injected faults). Now each is an error event and the rest runs."""
    def broken(*args, **kwargs):
        raise RuntimeError("injected")

    if target == "setpoint_summary":
        monkeypatch.setattr(flight_mod, "setpoint_summary", broken)
    else:  # the link closed, then the call raised
        original = flight_mod.open_link

        def open_link(**kwargs):
            link = original(**kwargs)
            close = link.close

            def closing():
                close()
                broken()

            link.close = closing
            return link

        monkeypatch.setattr(flight_mod, "open_link", open_link)
    uri = sim_uri()
    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri)
    wait_for_stop(uri)
    assert not result.aborted, result.cause
    s = check_closed_with_stop(result)
    assert s["setpoints"].data["tick"].max() == len(load_plan("hover-check").compile()) - 1
    what = "the summary" if target == "setpoint_summary" else "closing the link"
    assert any(e.text.startswith(f"{what} failed after the stop (RuntimeError: injected)")
               for e in s.events() if e.level == "error")


def test_a_listener_raising_systemexit_lands_records_and_then_exits(sim_uri, tmp_path):
    """A listener's SystemExit went through the runner's ``except Exception``: a bare stop, no
    descent, no cause in the file. Now it is the cause, the flight descends, the file closes
    with the stop, and then the SystemExit goes on up."""
    class Quitting:
        def begin(self, **_kw) -> None: ...
        def end(self, **_kw) -> None: ...

        def rows(self, stream, rows) -> None:
            if stream == "setpoints" and any(r[6] == 20 for r in rows):
                raise SystemExit(3)

    uri = sim_uri()
    with pytest.raises(SystemExit) as exit_info:
        fly_plan(plan="hover-check", out=tmp_path, uri=uri, listeners=[Quitting()])
    assert exit_info.value.code == 3
    wait_for_stop(uri)
    (path,) = tmp_path.glob("*.h5")
    s = open_session(path)
    summary = s.json_meta("summary")
    assert s.closed_cleanly and summary["aborted"]
    assert summary["cause"] == "Quitting.rows failed (SystemExit: 3): the flight ends"
    sp = s["setpoints"].data
    assert sp["tick"].max() < 25 and (sp["tick"] == -1).sum() > 5  # descended, then the stop
    assert sp["thrust"][-1] == 0 and sp["roll"][-1] == 0


def test_a_summary_that_fails_still_says_whether_the_flight_aborted(sim_uri, tmp_path,
                                                                   monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("injected")

    monkeypatch.setattr(flight_mod, "setpoint_summary", broken)
    monkeypatch.setattr(flight_mod._Runner, "preflight", lambda self: self.journal.cause(
        "injected cause") or True)
    uri = sim_uri()
    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri)
    wait_for_stop(uri)
    assert result.aborted and result.cause == "injected cause"
    assert result.summary["aborted"] and result.summary["cause"] == "injected cause"
    assert "summary failed" in result.summary["error"]
    assert open_session(result.path).json_meta("summary")["aborted"]


def test_a_recorder_raising_no_exception_still_says_what_the_file_lacks(sim_uri, tmp_path,
                                                                       monkeypatch):
    """A KeyboardInterrupt from the recorder itself took the listeners' SystemExit path: not
    a recording failure, so the runner never learnt where the file ends (review of the first
    fix). It is a recording failure, then the interrupt goes on up."""
    real, calls = Recorder.rows, []

    def failing(self, stream, rows):
        calls.append(stream)
        if len(calls) == 200:
            raise KeyboardInterrupt
        return real(self, stream, rows)

    monkeypatch.setattr(Recorder, "rows", failing)
    uri = sim_uri()
    with pytest.raises(KeyboardInterrupt):
        fly_plan(plan="hover-check", out=tmp_path, uri=uri)
    wait_for_stop(uri)
    (path,) = tmp_path.glob("*.h5")
    summary = open_session(path).json_meta("summary")
    assert summary["aborted"]
    assert summary["cause"] == "recording failed: Recorder.rows failed (KeyboardInterrupt: )"
