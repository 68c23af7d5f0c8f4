"""``groundstation info`` as text: stream and phase names are what the user types (``--inputs``,
``--window``), so a narrow terminal never cuts them; the events stream shows no internal field."""

from __future__ import annotations

import re

import pytest
from click.testing import CliRunner

from cfsession import SessionWriter, standard_streams
from cfsession.schema import log_block_spec
from groundstation.cli import main as gs

LONG = "stateEstimate+controller+motor+2-more"
VARIABLES = [("stateEstimate.x", "float"), ("controller.actuatorThrust", "float"),
             ("controller.cmd_thrust", "float"), ("controller.r_roll", "float"),
             ("controller.pitchRate", "float"), ("motor.m1", "uint16_t")]


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    path = tmp_path_factory.mktemp("info") / "s.h5"
    spec = log_block_spec(name=LONG, variables=VARIABLES, period_s=0.01)
    with SessionWriter(path, streams=[spec, *standard_streams()]) as w:
        w.phase(t=0.0, phase_id=0, name="excitation-long-name-1", kind="excitation")
        w.event(t=0.0, text="an event whose text is longer than one row " * 10)
        w.extend(LONG, [(0.01 * k, 10 * k, 1.0, 2.0, 3.0, 4.0, 5.0, 6) for k in range(100)])
    return path


@pytest.mark.parametrize("width", [40, 60, 80, 120])
def test_names_are_never_cut(session, width):
    res = CliRunner().invoke(gs, ["info", str(session), "--width", str(width)])
    assert res.exit_code == 0, res.output
    assert "…" not in res.output
    lines = res.output.splitlines()
    assert all(len(line.rstrip()) <= width for line in lines)
    if width >= 80:  # room for the names: the other columns give way, names stay on one line
        assert any(line.startswith(LONG + " ") for line in lines)
        assert any(line.startswith("excitation-long-name-1 ") for line in lines)
    else:  # no room even so: a name folds (whole, over lines), never ends in an ellipsis
        column = [line.split()[0] for line in lines if line[:1].strip()]
        assert LONG in "".join(column)


def test_every_field_name_is_whole_at_80_columns(session):
    res = CliRunner().invoke(gs, ["info", str(session), "--width", "80"])
    text = re.sub(r"\s+", "", res.output)  # a folded name joins up again
    for var, _ in VARIABLES:
        assert var.split(".")[1] in text


def test_the_events_stream_shows_no_internal_field(session):
    res = CliRunner().invoke(gs, ["info", str(session), "--width", "120"])
    [row] = [line for line in res.output.splitlines() if line.startswith("events ")]
    assert "cont" not in row
    assert "level, source, text (1 event)" in row


def test_a_model_file_is_named_as_one(tmp_path):
    import numpy as np

    import sysid

    path = sysid.StateSpaceModel(A=np.eye(1) * 0.5, B=np.ones((1, 1)), C=np.ones((1, 1)),
                                 dt=0.02).save(tmp_path / "m.h5")
    res = CliRunner().invoke(gs, ["info", str(path)])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert res.output.rstrip().endswith("a model file (sysid compare, sysid export read it)")


def test_the_files_own_text_is_shown_as_text_not_markup(tmp_path):
    """Text from the file ("[/x]" in a phase kind, a stream kind, the uri, an event, a problem)
    raised rich's MarkupError, a traceback, in `info` and `info --events`."""
    path = tmp_path / "s.h5"
    spec = log_block_spec(name="gyro", variables=[("gyro.x", "float")], period_s=0.02)
    with SessionWriter(path, streams=[spec, *standard_streams()],
                       metadata={"uri": "radio://[/u]", "plan_name": "[/p]"}) as w:
        w.phase(t=0.0, phase_id=0, name="[/n]", kind="[/k]")
        w.event(t=0.0, text="console: [/e] done")
        w.extend("gyro", [(0.02 * k, 20 * k, 1.0) for k in range(10)])
    import h5py

    with h5py.File(path, "a") as f:
        f["gyro"].attrs["kind"] = "[/s]"
        f["gyro"].attrs["period_s"] = "[/q]"  # listed as a problem, its value quoted
    res = CliRunner().invoke(gs, ["info", "--events", str(path)])
    assert res.exit_code == 0, res.output
    for text in ("radio://[/u]", "[/p]", "[/n]", "[/k]", "[/e] done", "[/s]", "'[/q]'"):
        assert text in res.output, text


def test_the_phase_table_lists_at_most_max_phase_rows(tmp_path, monkeypatch):
    """A file of 200 000 phase rows (2 MB) kept `info` laying out its table for minutes."""
    from groundstation.commands import info

    monkeypatch.setattr(info, "MAX_PHASE_ROWS", 3)
    path = tmp_path / "s.h5"
    with SessionWriter(path, streams=standard_streams()) as w:
        for k in range(5):
            w.phase(t=float(k), phase_id=k, name=f"hover-{k}", kind="hover")
    res = CliRunner().invoke(gs, ["info", str(path)])
    assert res.exit_code == 0, res.output
    assert "hover-2" in res.output and "hover-3" not in res.output
    assert "... 2 more phases (--json lists them)" in res.output


def test_several_files_are_each_described_and_a_bad_one_is_its_line(session, tmp_path):
    """``info sessions/*.h5``: every readable file described, each unreadable one its error
    line in its place, exit 2; with --json a list of the readable ones."""
    import json

    bad = tmp_path / "notes.h5"
    bad.write_text("not a session")
    runner = CliRunner()
    res = runner.invoke(gs, ["info", str(session), str(bad), str(session), "--width", "120"])
    assert res.exit_code == 2
    assert res.stdout.count(f"{session} schema") == 2
    errors = res.stderr.splitlines()
    assert len(errors) == 2 and str(bad) in errors[0]
    assert errors[1] == "error: 1 of 3 files could not be read (above)"
    res = runner.invoke(gs, ["info", str(session), str(session), "--json"])
    assert res.exit_code == 0
    assert [d["path"] for d in json.loads(res.stdout)] == [str(session)] * 2


def test_a_file_not_closed_says_it_may_still_be_recording(session, tmp_path):
    """A flight still recording read as "writer died" to an engineer who ran info on it."""
    import shutil

    import h5py

    live = tmp_path / "live.h5"
    shutil.copy(session, live)
    with h5py.File(live, "r+") as f:
        f.attrs["closed_cleanly"] = 0
    res = CliRunner().invoke(gs, ["info", str(live), "--width", "200"])
    assert res.exit_code == 0, res.output
    assert "NOT closed cleanly (still being written, or its writer died)" in res.stdout
