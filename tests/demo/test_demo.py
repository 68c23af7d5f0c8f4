"""The README's main command: two simulated PRBS flights, IEM, validation on the second."""

from __future__ import annotations

import json
import re

from click.testing import CliRunner

import groundstation.sim as gsim
from cfsession import open_session
from groundstation.cli import main
from sysid import load_model
from sysid.pole_format import pole_cells, pole_rows


def test_demo_flies_identifies_and_validates(tmp_path):
    try:
        res = CliRunner().invoke(main, ["demo", "--out", str(tmp_path), "--speed", "40"])
    finally:
        gsim.close_all()
    assert res.exit_code == 0, res.output
    assert "IEM model poles" in res.output and "1-step prediction" in res.output
    summary = json.loads((tmp_path / "demo-summary.json").read_text())
    ident, val = (open_session(p) for p in summary["sessions"])
    for s in (ident, val):  # whole flights, cleanly recorded, excitation airborne
        assert s.closed_cleanly and not s.problems
        t0, t1 = s.phase_window("excitation")
        z = s["altitude"]
        assert z.values()[(z.time > t0 + 1) & (z.time < t1)].min() > 0.2
    # the validation flight flew a different PRBS realisation
    assert ident.meta["plan_text"] != val.meta["plan_text"]
    model = load_model(summary["model"])
    assert model.A.shape == (8, 8) and model.B.shape == (8, 4) and model.C.shape == (6, 8)
    for row in pole_cells(pole_rows(model.poles(), dt=model.dt)):  # the one pole formatter
        assert re.search(r"\s+".join(map(re.escape, row)), res.output), row
    # the default model is stable by default (issue 10): rate dynamics integrate, so poles sit
    # at |z| ~ 1, but none beyond 1.01 (the old default refinement put them at 1.02-1.05)
    assert max(abs(p) for p in model.poles()) <= 1.01
    # The simulated vehicle's rate dynamics are captured: one-step prediction of the gyro on
    # the held-out flight (channels 3..5) well above chance. Measured over 7 runs (two flights
    # each, hosts loaded): 57-91 % per channel, mean 61-83 %; the flights (and so the model)
    # vary with host timing, hence a floor on the mean and a low one per channel.
    gyro_1step = summary["fits"]["1-step prediction"][3:]
    assert sum(gyro_1step) / 3 > 50.0 and min(gyro_1step) > 15.0, gyro_1step
    assert summary["predictor_stable"]
