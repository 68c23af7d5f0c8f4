"""Text output fits where it goes (a terminal, ``| cat``, ``--width``), and every pole table
is the one formatter's (MATLAB ``damp`` conventions)."""

from __future__ import annotations

import math
import re

import numpy as np
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
    assert setpoints.rstrip().endswith("thrust [PWM (0-65535)], phase_id, tick")  # one line
    res = CliRunner().invoke(gs_main, ["info", str(session), "--width", "60"])
    assert res.exit_code == 0 and max(len(ln) for ln in res.output.splitlines()) <= 60


@pytest.mark.parametrize("width", [90, 40])
def test_plan_show_honours_width_when_piped(width):
    res = CliRunner().invoke(gs_main, ["plan", "show", "pitch-only", "--width", str(width),
                                       "--height", "3"])
    assert res.exit_code == 0, res.output
    plot = [ln for ln in res.output.splitlines() if "│" in ln]
    assert len(plot) == 4 * 3  # 4 axes x 3 rows: no row wrapped onto a second line
    assert {len(ln) for ln in plot} == {width + 10}  # 8 label + " │" + width columns


def test_pole_formatter_follows_matlab_damp():
    dt = 0.02
    wn, zeta = 2 * math.pi * 2.0, 0.3
    s = complex(-zeta * wn, wn * math.sqrt(1 - zeta**2))
    pair = np.exp(np.array([s, s.conjugate()]) * dt)
    rows = pole_rows([0.99, *pair, 1.01, 0.0], dt=dt)
    assert [r["abs"] for r in rows] == sorted((r["abs"] for r in rows), reverse=True)
    unstable, real, a, b, zero = rows  # |z|: 1.01, 0.99, 0.93 (pair), 0
    assert unstable["tau_s"] is None and pole_cells([unstable])[0][-1] == "unstable"
    for r in (a, b):  # a complex pair: its natural frequency and damping ratio
        assert r["freq_hz"] == pytest.approx(2.0) and r["damping"] == pytest.approx(0.3)
        assert r["tau_s"] == pytest.approx(1 / (zeta * wn))
    assert a["im"] < 0 < b["im"]  # conjugates adjacent, negative first
    # a real pole has a natural frequency (not 0.00 Hz) and damping 1
    assert real["freq_hz"] == pytest.approx(-math.log(0.99) / dt / (2 * math.pi))
    assert real["damping"] == 1.0 and real["tau_s"] == pytest.approx(-dt / math.log(0.99))
    assert zero["damping"] == 1.0 and zero["tau_s"] == 0.0
    assert pole_cells([real])[0] == ("1", "0.9900+0.0000j", "0.9900", "0.0", "0.08", "1.000",
                                     "1.99")


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
