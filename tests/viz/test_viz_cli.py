"""`groundstation replay` and `groundstation plan show --rrd`: files written, one-line errors."""

from __future__ import annotations

import logging
import socket

import h5py
import numpy as np
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main
from groundstation.plan import load_plan
from tests.viz.rrd import load
from tests.viz.sessions import N_LOG, write_session


def test_replay_rrd(tmp_path):
    session = write_session(tmp_path / "flight.h5")
    out = tmp_path / "out" / "flight.rrd"  # its folder made, as every output's
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd", str(out)])
    assert res.exit_code == 0, res.output
    assert f"wrote {out}" in res.output
    ents = load(out)
    assert len(ents["/gyro/z"].scalars()) == N_LOG
    assert [s[0] for s in ents["/phase"].rows["StateChange:state"]][-1] == "land (landing)"


def test_replay_of_a_damaged_session_warns_each_problem_naming_the_file(tmp_path, caplog):
    """Replayed as far as it reads (the rows before the damage), never in silence."""
    session = write_session(tmp_path / "flight.h5")
    with h5py.File(session, "r") as f:
        info = f["gyro/data"].id.get_chunk_info(2)
    raw = bytearray(session.read_bytes())
    raw[info.byte_offset: info.byte_offset + info.size] = b"\xff" * info.size
    session.write_bytes(bytes(raw))
    with h5py.File(session, "r+") as f:  # and its writer died
        f.attrs["closed_cleanly"] = 0
    problems = open_session(session).problems
    assert len(problems) == 2
    out = tmp_path / "flight.rrd"
    with caplog.at_level(logging.WARNING, logger="groundstation.commands.replay"):
        res = CliRunner().invoke(main, ["replay", str(session), "--rrd", str(out)])
    assert res.exit_code == 0, res.output
    assert [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING] == [
        f"{session}: problem: {p}" for p in problems]
    assert 0 < len(load(out)["/gyro/z"].scalars()) < N_LOG


def test_replay_errors_are_one_line(tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["replay", str(tmp_path / "missing.h5"), "--rrd", "x.rrd"])
    assert res.exit_code == 2 and res.output.strip().count("\n") == 0
    assert "missing.h5: no such file" in res.output
    session = write_session(tmp_path / "flight.h5")
    res = runner.invoke(main, ["replay", str(session), "--rrd", str(tmp_path / "a.rrd"),
                               "--view", "serve"])
    assert res.exit_code == 2 and "pass only one" in res.output
    assert not (tmp_path / "a.rrd").exists()
    with socket.socket() as busy:  # a busy web viewer port: one line, nothing served
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        res = runner.invoke(main, ["replay", str(session), "--view", "serve", "--port",
                                   str(port)])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert f"error: port {port} is in use" in res.output and "--port" in res.output


def test_plan_show_rrd_equals_the_schedule(tmp_path):
    out = tmp_path / "plan.rrd"
    res = CliRunner().invoke(main, ["plan", "show", "prbs-3axis", "--rrd", str(out)])
    assert res.exit_code == 0, res.output
    schedule = load_plan("prbs-3axis").compile()
    ents = load(out)
    for axis in ("roll", "pitch", "yaw_rate", "thrust"):
        e = ents[f"/setpoints/{axis}"]
        np.testing.assert_allclose(e.scalars(), getattr(schedule, axis), rtol=1e-6)
        np.testing.assert_allclose(e.times["host_time"], schedule.t, atol=1e-9)
    phase = ents["/phase"]
    assert [s[0] for s in phase.rows["StateChange:state"]] == [
        f"{p.name} ({p.kind})" for p in schedule.phases]
    np.testing.assert_allclose(phase.times["host_time"], [p.start for p in schedule.phases])
    assert "prbs-3axis" in ents["/session"].static["TextDocument:text"][0]
