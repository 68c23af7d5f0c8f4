"""The README's main command: two simulated PRBS flights, IEM, validation on the second."""

from __future__ import annotations

import json
import re

import pytest
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
    n = summary["order"]  # chosen by validation on the last 30 % of flight 1
    assert model.A.shape == (n, n) and model.B.shape == (n, 4) and model.C.shape == (6, n)
    assert "chosen:" in res.output
    # "5116 samples, 16.86 s" read as 5116 samples lasting 16.86 s (they last 102.3 s; 16.86 s
    # was the identification's run time)
    assert re.search(rf"IEM: order {n}, past \d+, future \d+, {summary['samples']} samples "
                     rf"\({summary['samples'] * model.dt:.1f} s of flight\), identified in "
                     r"\d+\.\d\d s; stable", res.output), res.output
    for row in pole_cells(pole_rows(model.poles(), dt=model.dt)):  # the one pole formatter
        assert re.search(r"\s+".join(map(re.escape, row)), res.output), row
    # the default model is stable by default (issue 10): rate dynamics integrate, so poles sit
    # at |z| ~ 1, but none beyond 1.01 (the old default refinement put them at 1.02-1.05)
    assert max(abs(p) for p in model.poles()) <= 1.01
    # The simulated vehicle's rate dynamics are captured on the held-out flight (gyro channels
    # 3..5). Horizons and order are chosen by validation, and the flights differ run to run
    # (thread timing against the simulation, more so on a busy host), so the choice does too
    # (order 9-12): over 12 runs 1-step 67-98 %, 2 s windowed simulation 28-86 % per channel
    # (with the thesis' fixed 8/60/17 the same flights gave -10..78 % 1-step: why the demo
    # chooses by validation). The floors are what every run must reach: a one-step prediction
    # far better than the mean, and a simulation that beats the channel mean (an unstable or
    # drifting model, the old default, went negative).
    gyro_1step = summary["fits"]["1-step prediction"][3:]
    [simulated] = [k for k in summary["fits"] if k.startswith("simulation")]
    assert simulated.endswith(" s windows"), simulated  # near-integrating: windows, as compare
    gyro_sim = summary["fits"][simulated][3:]
    assert min(gyro_1step) > 50.0, gyro_1step
    assert min(gyro_sim) > 0.0, gyro_sim
    assert summary["predictor_stable"]
    # not on a terminal: progress as plain lines on stderr, the flights' and the choice's
    assert re.search(r"^\[fly\] t +\d+\.\d/112\.3 s  phase prbs", res.stderr, re.M), res.stderr
    assert re.search(r"^identifying with IEM .*\(100 %\).*done$", res.stderr, re.M), res.stderr
    # a second demo into the same folder does not replace the first one's results unasked
    again = CliRunner().invoke(main, ["demo", "--out", str(tmp_path)])
    assert again.exit_code == 2 and "already holds a demo's results" in again.stderr
    assert "--force" in again.stderr and len(again.stderr.strip().splitlines()) == 1
    assert json.loads((tmp_path / "demo-summary.json").read_text()) == summary


@pytest.mark.parametrize(("speed", "ok"), [("inf", True), ("INF", True), ("nan", False),
                                           ("0.5", False), ("1e9", False)])
def test_demo_speed_is_a_factor_or_flat_out(speed, ok):
    """``--speed inf`` flies flat out in lock-step (the same flights every run:
    tests/flight/test_repeatable.py); anything else must be a finite factor in 1..100."""
    from groundstation.commands.demo import _Speed

    opt = _Speed(min=1, max=100)
    if ok:
        assert opt.convert(speed, None, None) == float("inf")
        return
    res = CliRunner().invoke(main, ["demo", "--speed", speed])
    assert res.exit_code == 2 and "--speed" in res.output and "Traceback" not in res.output


def test_fixed_horizons_the_flight_cannot_support_are_one_line_keeping_the_flights(
        tmp_path, monkeypatch):
    """``demo --order 40 --past 1 --future 2`` ended in sysid's NoStableModel traceback.
    (The demo's plan with 20.5 s of its 102.3 s PRBS: past 1 bounds the rank whatever the
    length, and the two whole flights cost 4 s each.)"""
    import groundstation.commands.demo as demo
    from tests.flight.conftest import plan_variant

    short = plan_variant("prbs-3axis", **{"duration = 102.3": "duration = 20.5"})
    monkeypatch.setattr(demo, "load_plan", lambda name: short if name == "prbs-3axis"
                        else pytest.fail(f"the demo loads {name}"))
    try:
        res = CliRunner().invoke(main, ["demo", "--out", str(tmp_path), "--speed", "inf",
                                        "--order", "40", "--past", "1", "--future", "2"])
    finally:
        gsim.close_all()
    assert res.exit_code == 2, res.output
    line = res.output.strip().splitlines()[-1]
    assert line.startswith("error: identification failed: all 1 models of the grid failed: "
                           "order=40 exceeds the rank available")
    # flight 1 first (on sim://0): two short flights in the same second are named
    # prbs-3axis-<time>.h5 and prbs-3axis-<time>-2.h5, which sort the other way round
    flights = sorted(tmp_path.glob("*.h5"), key=lambda p: open_session(p).meta["uri"])
    assert len(flights) == 2 and line.endswith(f"the sessions are kept: {flights[0]} "
                                               f"{flights[1]}")
    assert all(open_session(p).closed_cleanly for p in flights)
