"""Text output fits where it goes (a terminal, ``| cat``, ``--width``), and every pole table
is the one formatter's (its conventions: tests/sysid/test_pole_format.py)."""

from __future__ import annotations

import re

import pytest
from click.testing import CliRunner

from groundstation.cli import main as gs_main
from sysid.cli import main as sysid_main
from sysid.model import load_model
from sysid.pole_format import pole_cells, pole_rows
from tests.sysid.flights import known_system, write_flight
from tests.viz.sessions import write_session

BOX = set("│┃┏┡━─┼╇┗┛┓┌┐└┘")


def test_info_piped_is_a_plain_unwrapped_table(tmp_path):
    session = write_session(tmp_path / "flight.h5")
    res = CliRunner().invoke(gs_main, ["info", str(session)])  # CliRunner: not a terminal
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    assert not BOX & set(res.output)
    header = next(ln for ln in lines if ln.startswith("stream"))
    assert "fields [unit]" in header  # a title, not eaten as markup
    (setpoints,) = [ln for ln in lines if ln.startswith("setpoints ")]
    assert setpoints.endswith("thrust [PWM (0-65535)], phase_id, tick")  # one line
    # a plain table padded its last column: every shorter row ended in spaces
    assert not [ln for ln in lines if ln.endswith(" ")]
    res = CliRunner().invoke(gs_main, ["info", str(session), "--width", "60"])
    assert res.exit_code == 0 and max(len(ln) for ln in res.output.splitlines()) <= 60


@pytest.mark.parametrize("width", [90, 40])
def test_plan_show_honours_width_when_piped(width):
    res = CliRunner().invoke(gs_main, ["plan", "show", "pitch-only", "--width", str(width),
                                       "--height", "3"])
    assert res.exit_code == 0, res.output
    plot = [ln for ln in res.output.splitlines() if "│" in ln]
    assert len(plot) == 4 * 3  # 4 axes x 3 rows: no row wrapped onto a second line
    # 8 label + " │" + width columns (piped, a row's trailing blanks are trimmed)
    assert max(len(ln) for ln in plot) == width + 10


def test_identify_prints_the_formatters_table(tmp_path):
    flight = write_flight(tmp_path / "f.h5", system=known_system(), seed=5, n=1200)
    res = CliRunner().invoke(sysid_main, ["identify", str(flight.path), "--order", "4",
                                          "--past", "20", "--future", "10", "--out",
                                          str(tmp_path / "m.h5")])
    assert res.exit_code == 0, res.output
    model = load_model(tmp_path / "m.h5")
    cells = pole_cells(pole_rows(model.poles(), dt=model.dt))
    for row in cells:  # every pole on one line, in the formatter's order and words
        assert re.search(r"\s+".join(map(re.escape, row)), res.output), (row, res.output)


def test_info_shows_a_sessions_control_characters_escaped(tmp_path):
    """A session made elsewhere whose phase name and event text hold a screen clear, a
    carriage return and a bell: ``info`` printed them raw (review); escaped now, and a log
    record quoting such text is one line with them escaped too."""
    import logging

    import h5py
    import numpy as np

    from cfcommon.cli import _OneLineRecords
    from tests.viz.test_replay_hostile import EVENTS, PHASES, _craft

    phases = ("phases", "phases", PHASES, [(0.1, 0, b"ho\x1b[2Jver\r", b"hover")])
    session = _craft(tmp_path / "s.h5", extra=phases)
    with h5py.File(session, "a") as f:
        g = f.create_group("events")
        g.attrs["kind"] = "events"
        g.create_dataset("data", data=np.array([(0.2, 3, b"runner", b"bell\x07X", 0)],
                                                dtype=EVENTS))
    res = CliRunner().invoke(gs_main, ["info", str(session), "--events"])
    assert res.exit_code == 0, res.output
    assert not re.search("[\x00-\x09\x0b-\x1f\x7f-\x9f]", res.output), repr(res.output)
    assert r"ho\x1b[2Jver\r" in res.output and r"bell\x07" in res.output
    record = logging.LogRecord("x", logging.WARNING, __file__, 1, "phase %s", ("a\x1b[2J\nb",),
                               None)
    assert _OneLineRecords(tracebacks=False).format(record) == r"warning: phase a\x1b[2J\nb"
