"""``groundstation fly`` for validation flights (--advance, --seed, --name), its progress off a
terminal, a view that cannot start, and a flight that never connects."""

from __future__ import annotations

import json
import socket

import usb.core
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main
from groundstation.plan import parse_plan
from groundstation.plan.variants import advanced_seed
from tests.flight.conftest import plan_variant


def _short_plan(tmp_path):
    """pitch-only with a 3 s PRBS phase: a validation flight in well under a second at 20x."""
    plan = plan_variant("pitch-only", **{"duration = 25.5": "duration = 3.0",
                                         "duration = 5.0 ": "duration = 2.0 "})
    path = tmp_path / "short.toml"
    path.write_text(plan.text)
    return path


def _prbs_seed(text: str) -> int:
    plan = parse_plan(text=text, source="flown", name="flown")
    return next(e.seed for p in plan.phases for e in p.excitation if e.signal == "prbs")


def _one_line_error(res, *words):
    assert res.exit_code == 2, res.output
    assert res.output.count("\n") == 1 and "Traceback" not in res.output, res.output
    assert all(w in res.output for w in words), res.output


def test_validation_flight_advance_and_name(sim_uri, tmp_path):
    plan = _short_plan(tmp_path)
    res = CliRunner().invoke(main, ["fly", str(plan), "--uri", sim_uri(), "--out",
                                    str(tmp_path / "s"), "--advance", "7", "--name",
                                    "validation", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert "/pitch-only-validation-" in summary["file"]
    s = open_session(summary["file"])
    assert s.meta["tag"] == "validation"
    info = CliRunner().invoke(main, ["info", summary["file"]])
    assert "plan pitch-only  tag validation" in info.output
    flown = s.meta["plan_text"]
    assert _prbs_seed(flown) == advanced_seed(register_length=8, seed=1, chips=7)
    # the flown setpoints are the advanced PRBS, not the shipped one
    sp = s["setpoints"].data
    shipped = parse_plan(text=plan.read_text(), source="x", name="x").compile()
    advanced = parse_plan(text=flown, source="x", name="x").compile()
    k = sp["tick"] >= 0
    assert (sp["pitch"][k] == advanced.pitch[sp["tick"][k]]).all()
    assert (advanced.pitch != shipped.pitch).any()
    # progress off a terminal: plain lines on stderr, one per phase at least
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("[fly] t")]
    for phase in ("takeoff", "prbs", "land", "ended"):
        assert any(f"phase {phase}" in ln for ln in lines), lines
    assert "packets motors" in lines[-1]


def test_seed_keeps_the_axes_lags_and_options_are_checked(sim_uri, tmp_path):
    plan = _short_plan(tmp_path)
    res = CliRunner().invoke(main, ["fly", str(plan), "--uri", sim_uri(), "--out",
                                    str(tmp_path / "s"), "--seed", "77", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert _prbs_seed(open_session(summary["file"]).meta["plan_text"]) == 77
    for args, words in ((["--seed", "300"], ["seed 300", "1..255"]),
                        (["--seed", "3", "--advance", "2"], ["only one"]),
                        (["--name", "../x"], ["--name", "letters"])):
        res = CliRunner().invoke(main, ["fly", str(plan), "--uri", sim_uri(), "--out",
                                        str(tmp_path / "never"), *args])
        assert res.exit_code == 2, res.output
        assert all(w in res.output for w in words), res.output
        assert not (tmp_path / "never").exists()


def test_no_radio_leaves_no_empty_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(usb.core, "find", lambda **kw: iter(()))
    out = tmp_path / "new" / "sessions"
    res = CliRunner().invoke(main, ["fly", "hover-check", "--out", str(out), "--timeout", "1",
                                    "--uri", "radio://0/80/2M/E7E7E7E7E7"])
    assert res.exit_code == 2, res.output
    assert "Crazyradio" in res.output
    assert not (tmp_path / "new").exists()  # nor the parent it had to create
    existing = tmp_path / "kept"
    existing.mkdir()
    res = CliRunner().invoke(main, ["fly", "hover-check", "--out", str(existing), "--timeout",
                                    "1", "--uri", "radio://0/80/2M/E7E7E7E7E7"])
    assert res.exit_code == 2 and existing.is_dir()  # a folder the user made stays


def test_busy_port_stops_before_flying(sim_uri, tmp_path):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        uri = sim_uri()
        res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--view", "serve",
                                        "--port", str(port), "--out", str(tmp_path / "s")])
        _one_line_error(res, f"port {port} is in use", "--port")
        assert not (tmp_path / "s").exists()
