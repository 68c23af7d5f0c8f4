"""``.rrd`` outputs of ``replay`` and ``plan show``: never an input, an existing file only with
``--force``, a missing folder made, checked before any work (one line, exit 2, inputs
unchanged)."""

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


def test_replay_rrd_makes_a_missing_folder_and_refuses_a_wrong_suffix(tmp_path):
    session = write_session(tmp_path / "flight.h5")
    out = tmp_path / "rrd" / "flight.rrd"  # made as import --out makes its folder
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd", str(out)])
    assert res.exit_code == 0, res.output
    assert out.stat().st_size > 0
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd",
                                    str(tmp_path / "nope" / "f.h5")])
    _one_line_error(res)
    assert ".rrd" in res.output and not (tmp_path / "nope").exists()


def test_an_existing_rrd_is_replaced_only_with_force(tmp_path):
    """The review's case: replay wrote rrd/flight.rrd, then plan show --rrd on the same name
    replaced it with the plan's (117 KB for 975 KB). Now every --rrd refuses it, on one line
    naming --force, before any work (a session that does not exist is not even opened)."""
    session = write_session(tmp_path / "flight.h5")
    out = tmp_path / "rrd" / "flight.rrd"
    assert CliRunner().invoke(main, ["replay", str(session), "--rrd", str(out)]).exit_code == 0
    flight = _digest(out)
    for args in (["plan", "show", "hover-check", "--rrd", str(out)],
                 ["replay", str(session), "--rrd", str(out)],
                 ["replay", str(tmp_path / "absent.h5"), "--rrd", str(out)]):
        res = CliRunner().invoke(main, args)
        _one_line_error(res)
        assert "already exists; pass --force" in res.output, args
        assert _digest(out) == flight
    res = CliRunner().invoke(main, ["plan", "show", "hover-check", "--rrd", str(out), "--force"])
    assert res.exit_code == 0, res.output
    assert _digest(out) != flight
    res = CliRunner().invoke(main, ["replay", str(session), "--rrd", str(out), "--force"])
    assert res.exit_code == 0, res.output
    assert out.stat().st_size > 0


def test_plan_show_rrd_checks_the_output_first(tmp_path):
    plan = tmp_path / "mine.toml"
    res = CliRunner().invoke(main, ["plan", "show", "hover-check", "--json"])
    assert res.exit_code == 0
    res = CliRunner().invoke(main, ["plan", "show", "hover-check", "--rrd",
                                    str(tmp_path / "pad.mat" / "p.rrd")])
    _one_line_error(res)
    assert "named like a file" in res.output and not (tmp_path / "pad.mat").exists()
    plan.write_text("not a plan")
    before = _digest(plan)
    res = CliRunner().invoke(main, ["plan", "show", str(plan), "--rrd", str(plan)])
    _one_line_error(res)
    assert _digest(plan) == before
    session = write_session(tmp_path / "flight.h5")
    res = CliRunner().invoke(main, ["plan", "show", "hover-check", "--rrd", str(session)])
    _one_line_error(res)
    assert session.read_bytes()[:4] == b"\x89HDF"


def test_plan_show_json_with_rrd_writes_both(tmp_path):
    """--json beside --rrd ignored the recording in silence: both now, the JSON alone on
    standard output."""
    import json

    out = tmp_path / "plan.rrd"
    res = CliRunner().invoke(main, ["plan", "show", "hover-check", "--json", "--rrd", str(out)])
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["name"] == "hover-check"
    assert res.stderr.strip() == f"wrote {out}" and out.stat().st_size > 0
