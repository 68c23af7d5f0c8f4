"""``.rrd`` outputs of ``replay`` and ``plan show``: never an input, never a missing folder,
checked before any work (one line, exit 2, inputs unchanged)."""

from __future__ import annotations

import hashlib

from click.testing import CliRunner

from groundstation.cli import main
from tests.viz.sessions import write_session


def _digest(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _one_line_error(res) -> None:
    """Exit 2, no traceback, exactly one error line."""
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)
    errors = [ln for ln in res.output.splitlines() if ln.lower().startswith("error")]
    assert len(errors) == 1, res.output


def test_replay_never_writes_over_the_session(tmp_path):
    session = write_session(tmp_path / "pitch.h5")
    before = _digest(session)
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd", str(session)])
    _one_line_error(res)
    assert _digest(session) == before
    # the same file through another spelling of its path
    link = tmp_path / "alias.rrd"
    link.symlink_to(session)
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd", str(link)])
    _one_line_error(res)
    assert "input" in res.output and _digest(session) == before


def test_replay_rrd_refuses_a_missing_folder_and_wrong_suffix(tmp_path):
    session = write_session(tmp_path / "flight.h5")
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd",
                                    str(tmp_path / "nope" / "flight.rrd")])
    _one_line_error(res)
    assert "does not exist" in res.output and not (tmp_path / "nope").exists()
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd", str(tmp_path / "f.h5")])
    _one_line_error(res)
    assert ".rrd" in res.output and not (tmp_path / "f.h5").exists()


def test_replay_replaces_an_existing_rrd(tmp_path):
    session = write_session(tmp_path / "flight.h5")
    out = tmp_path / "flight.rrd"
    out.write_bytes(b"old")
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_bytes() != b"old"


def test_plan_show_rrd_checks_the_output_first(tmp_path):
    plan = tmp_path / "mine.toml"
    res = CliRunner().invoke(main, ["plan", "show", "hover-check", "--json"])
    assert res.exit_code == 0
    res = CliRunner().invoke(main, ["plan", "show", "hover-check", "--rrd",
                                    str(tmp_path / "missing" / "p.rrd")])
    _one_line_error(res)
    assert not (tmp_path / "missing").exists()
    plan.write_text("not a plan")
    before = _digest(plan)
    res = CliRunner().invoke(main, ["plan", "show", str(plan), "--rrd", str(plan)])
    _one_line_error(res)
    assert _digest(plan) == before
    session = write_session(tmp_path / "flight.h5")
    res = CliRunner().invoke(main, ["plan", "show", "hover-check", "--rrd", str(session)])
    _one_line_error(res)
    assert session.read_bytes()[:4] == b"\x89HDF"
