"""``groundstation fly`` when the session file's disk fills, a file size limit (``ulimit -f``)
is reached, or its folder is moved or deleted mid-flight: the flight still ends with the stop
setpoint delivered and recorded, the error is one line (exit 2) and never a crash or a
traceback, and the summary never names a file that is not there.

The disk tests fly at 5x: the recorder flushes every second of flight time when at least 0.1 s
of wall time has passed, so below 10x every flight second is flushed whatever the host's load,
and a refusal is noticed within a second of flight."""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner

import cfsession.saving as saving
import cfsession.writer as writer_mod
import groundstation.commands.fly as fly_cli
import groundstation.recorder as recorder_mod
from cfsession import open_session
from groundstation.cli import main
from groundstation.flight import FlightResult

from .checks import check_closed_with_stop, safety_events
from .conftest import wait_for_stop
from .test_robustness import never_connected, one_line_error

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="POSIX files and limits")


def _fly(uri: str, out: Path, *extra: str):
    return CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out", str(out),
                                     *extra])


def _summary(res) -> dict:
    return json.loads(res.output[res.output.index("{"):res.output.rindex("}") + 1])


def _act_at_tick(monkeypatch, tick: int, action) -> None:
    """``action()`` just before setpoint ``tick`` is sent (the runner's ``tick_hook``)."""
    fly_plan = fly_cli.fly_plan

    def hooked(**kw):
        return fly_plan(**{**kw, "tick_hook": lambda k: action() if k == tick else None})

    monkeypatch.setattr(fly_cli, "fly_plan", hooked)


def _allocations_refused_after(monkeypatch, first: int) -> None:
    """``posix_fallocate`` refuses (ENOSPC) any room beyond ``first`` bytes of a file: the
    disk is full once the session has grown past its first reserve."""
    real = os.posix_fallocate

    def fallocate(fd, offset, length):
        if offset + length > first:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, offset, length)

    monkeypatch.setattr(writer_mod.os, "posix_fallocate", fallocate)


def test_a_full_disk_aborts_and_the_landing_is_recorded(sim_uri, tmp_path, monkeypatch):
    monkeypatch.setattr(recorder_mod, "RESERVE_BYTES", 64 << 10)
    _allocations_refused_after(monkeypatch, 128 << 10)
    uri = sim_uri(speed=5)
    res = _fly(uri, tmp_path)
    line = one_line_error(res)
    assert line.startswith(f"error: flight aborted: disk full: no room left in {tmp_path} "
                           "for the session's next ")  # the reserve: room for the landing
    assert " KiB (No space left on device); session saved to " in line
    wait_for_stop(uri)
    path = Path(line.rsplit(" ", 1)[1])
    result = FlightResult(path=path, cause="disk full")
    s = check_closed_with_stop(result)  # whole, closed cleanly, the stop recorded
    assert safety_events(s)[0].text.startswith("disk full: no room left in")
    assert s["setpoints"].data["tick"].max() < 99  # aborted: the plan did not fly to its end
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_a_disk_without_room_for_a_session_is_refused_before_connecting(sim_uri, tmp_path,
                                                                        monkeypatch):
    _allocations_refused_after(monkeypatch, 0)
    uri = sim_uri()
    line = one_line_error(_fly(uri, tmp_path / "out"))
    assert "disk full: no room left in" in line and "KiB to start" in line
    assert never_connected(uri) and not (tmp_path / "out").exists()


CHILD = textwrap.dedent(
    """
    import resource, sys
    import groundstation.recorder as recorder
    recorder.RESERVE_BYTES = 16 << 10  # a hover-check session outgrows it
    resource.setrlimit(resource.RLIMIT_FSIZE, (60_000, 60_000))  # ulimit -f
    from groundstation.cli import main
    main(sys.argv[1:])
    """
)


def test_a_file_size_limit_aborts_with_one_line_and_a_readable_file(tmp_path):
    """A real ``RLIMIT_FSIZE``: the flight aborts, lands, and the session is whole (what did
    not fit while flying was kept in memory and saved compressed at close)."""
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, str(script), "fly", "hover-check", "--uri",
                           "sim://0?speed=5&seed=1", "--out", str(out)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-3000:])  # -11: h5py crashed
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    # the safety check's record when it fires, then the command's one error line, last
    errors = [ln for ln in proc.stderr.splitlines() if ln.startswith("error")]
    assert len(errors) == 2 and errors[0].startswith("error: safety: file size limit"), \
        proc.stderr
    errors = errors[1:]
    assert errors[0].startswith(f"error: flight aborted: file size limit reached writing in "
                                f"{out}: a file may not grow past 60000 bytes (ulimit -f); "
                                "session saved to ")
    (path,) = out.iterdir()
    assert errors[0].endswith(str(path))
    s = check_closed_with_stop(FlightResult(path=path, cause="limit"))
    assert safety_events(s)[0].text.startswith("file size limit reached")


def _fly_while(monkeypatch, uri: str, out: Path, action) -> tuple[dict, Path]:
    """``fly --json`` into ``out`` with ``action()`` done at tick 30: the summary and the file
    it names (the flight completed, exit 0)."""
    _act_at_tick(monkeypatch, 30, action)
    res = _fly(uri, out, "--json")
    assert res.exit_code == 0, res.output
    summary = _summary(res)
    return summary, Path(summary["file"])


def test_a_deleted_folder_is_made_again_with_the_session(sim_uri, tmp_path, monkeypatch):
    out = tmp_path / "out"
    summary, path = _fly_while(monkeypatch, sim_uri(), out, lambda: shutil.rmtree(out))
    assert path.parent == out and path.exists()
    (note,) = summary["file_notes"]
    assert "was deleted while being written" in note and str(path) in note
    s = check_closed_with_stop(FlightResult(path=path))
    assert s["setpoints"].data["tick"].max() == 99  # the whole plan, recorded


def test_a_renamed_folder_is_where_the_summary_says(sim_uri, tmp_path, monkeypatch):
    out, moved = tmp_path / "out", tmp_path / "moved"
    summary, path = _fly_while(monkeypatch, sim_uri(), out, lambda: out.rename(moved))
    assert path.parent == moved and path.exists() and not out.exists()
    assert summary["file_notes"] == [f"{out / path.name} was moved while being written; the "
                                     f"session is now {path}"]
    check_closed_with_stop(FlightResult(path=path))


def test_a_folder_replaced_by_a_file_puts_the_session_in_the_folder_above(sim_uri, tmp_path,
                                                                         monkeypatch):
    """The folder deleted and a file put in its place: the flight lands, and the session goes
    to the nearest folder above that takes it; the summary names it and a warning says why
    (exit 0, as for any deleted folder: the session is whole where the summary says)."""
    out = tmp_path / "out"

    def replace_folder():
        shutil.rmtree(out)
        out.write_text("not a folder")

    _act_at_tick(monkeypatch, 30, replace_folder)
    uri = sim_uri()
    res = _fly(uri, out, "--json")
    assert res.exit_code == 0, res.output
    summary = _summary(res)
    path = Path(summary["file"])
    assert path.parent == tmp_path and path.name.startswith("hover-check-")
    (note,) = summary["file_notes"]
    assert note == (f"{out / path.name} was deleted while being written (its folder removed?), "
                    "and writing it again there failed (File exists); the session was written, "
                    f"from the still open file, to {path} instead")
    assert out.read_text() == "not a folder"
    s = check_closed_with_stop(FlightResult(path=path))
    assert s["setpoints"].data["tick"].max() == 99


def test_a_session_that_cannot_be_written_anywhere_is_one_line(sim_uri, tmp_path, monkeypatch):
    """No folder takes it: the command says the session is lost instead of naming a file that
    is not there."""
    out = tmp_path / "out"
    monkeypatch.setattr(saving, "fallbacks", lambda original: [])

    def replace_folder():
        shutil.rmtree(out)
        out.write_text("not a folder")

    _act_at_tick(monkeypatch, 30, replace_folder)
    uri = sim_uri()
    res = _fly(uri, out)
    line = one_line_error(res)
    assert line.startswith(f"error: {out}/hover-check-") and line.endswith("the session is lost")
    assert "file none: the session could not be saved" in res.output
    wait_for_stop(uri)
    assert out.read_text() == "not a folder"


def test_the_recorded_file_reads_back_after_a_moved_folder(sim_uri, tmp_path, monkeypatch):
    """``groundstation info`` on the file the summary names."""
    out, moved = tmp_path / "out", tmp_path / "moved"
    _act_at_tick(monkeypatch, 50, lambda: out.rename(moved))
    res = _fly(sim_uri(), out, "--json")
    path = _summary(res)["file"]
    info = CliRunner().invoke(main, ["info", path])
    assert info.exit_code == 0 and "closed cleanly" in info.output
    assert f"file {Path(path).name}\n" in info.output and str(out) not in info.output
    assert open_session(path)["setpoints"].data["tick"].max() == 99


def test_writes_that_fail_mid_flight_keep_what_reached_the_disk(sim_uri, tmp_path,
                                                              monkeypatch):
    """Every write fails from setpoint 30 on (the disk taken by another program): the flight
    aborts and lands, nothing crashes, and the line says how much of the flight the file
    holds; the file reads as far as it goes, flagged."""
    real, full = os.pwrite, []

    def pwrite(fd, data, pos):
        if full:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data, pos)

    monkeypatch.setattr(writer_mod.os, "pwrite", pwrite)
    _act_at_tick(monkeypatch, 30, lambda: full.append(True))
    uri = sim_uri(speed=5)
    line = one_line_error(_fly(uri, tmp_path))
    wait_for_stop(uri)
    head, path = line.split("; session saved to ")
    assert head.startswith(f"error: flight aborted: disk full: no room left in {tmp_path} "
                           "(No space left on device); the file holds the flight up to ")
    assert head.endswith(" s only")
    until = float(head.rsplit(" up to ", 1)[1].split()[0])
    s = open_session(path)
    assert not s.closed_cleanly and s.problems
    ticks = s["setpoints"].data["tick"]
    assert 15 <= ticks.max() < 30  # flushed each second of flight before setpoint 30
    assert max(st.time.max() for st in s.streams.values() if len(st)) >= until
