"""What `sysid identify` says about the data it validates on: a fit below 0 % is warned of
(once, every channel named), a session given twice is refused, a --validate session that is
also identified from is warned of; and the fit it prints is `sysid compare`'s."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from click.testing import CliRunner

from sysid.cli import main
from sysid.comparison import CompareResult
from sysid.validate import below_mean_warning
from tests.sysid.flights import known_system, write_flight

FAST = ["--order", "4", "--past", "20", "--future", "10"]


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    d = tmp_path_factory.mktemp("valchecks")
    return {"ident": write_flight(d / "ident.h5", system=known_system(), seed=10).path,
            "same": write_flight(d / "same.h5", system=known_system(), seed=11).path,
            "other": write_flight(d / "other.h5", system=known_system(seed=99), seed=12).path}


def run(*args: object) -> object:
    return CliRunner().invoke(main, [str(a) for a in args])


def _result(fit: list[float]) -> CompareResult:
    return CompareResult(fit=np.array(fit), fits=np.array([fit]), y_model=(), y_measured=(),
                         x0=(), horizon=None, window=None, model_stable=True,
                         predictor_stable=True, diverged=False,
                         output_names=tuple(f"y{i}" for i in range(len(fit))))


def test_below_mean_warning_names_each_channel_under_zero_and_nothing_else() -> None:
    assert below_mean_warning([("simulation", _result([12.0, 0.0, np.nan]))], data="v.h5") is None
    line = below_mean_warning([("simulation, 2 s windows", _result([-43.2, 50.0, np.nan])),
                               ("1-step prediction", _result([5.0, -np.inf, 1.0]))],
                              data="v.h5")
    assert line is not None and "\n" not in line
    assert line.startswith("fit below 0 % on v.h5: y0 -43.2 % (simulation, 2 s windows), "
                           "y1 diverged (1-step prediction): ")
    assert "worse than a constant at their mean" in line and "--horizon" in line


def test_identify_warns_once_of_fits_below_zero_on_the_validation_flight(flights, caplog):
    """A model saved with fits below 0 % on its validation flight passed silently."""
    caplog.set_level(logging.WARNING)
    res = run("identify", flights["ident"], *FAST, "--validate", flights["other"], "--json")
    assert res.exit_code == 0, res.output
    fits = json.loads(res.stdout)["validation"]
    below = {name for row in fits for name, fit in row["fit_percent"].items()
             if fit is None or fit < 0}
    assert below  # a flight of another vehicle: the test needs at least one
    lines = [r.getMessage() for r in caplog.records if "fit below 0 %" in r.getMessage()]
    assert len(lines) == 1 and "on other.h5:" in lines[0]
    assert all(f"{name} " in lines[0] for name in below)
    caplog.clear()
    res = run("identify", flights["ident"], *FAST, "--validate", flights["same"], "--json")
    assert res.exit_code == 0, res.output
    assert min(v for row in json.loads(res.stdout)["validation"]
               for v in row["fit_percent"].values()) > 0
    assert "fit below 0 %" not in caplog.text


def test_a_session_given_twice_is_refused_in_one_line(flights) -> None:
    """`identify A A` read "2 experiments" and held out the second copy of the first."""
    res = CliRunner().invoke(main, ["identify", str(flights["ident"]), str(flights["ident"]),
                                    *FAST], prog_name="sysid")
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == [
        f"error: Invalid value for SESSIONS: {flights['ident']} is given twice: one flight "
        "would count as two experiments (and be held out to validate the models it chose); "
        "give each session once (see 'sysid identify -h')"]
    link = flights["ident"].with_name("link.h5")
    link.symlink_to(flights["ident"])
    res = run("identify", flights["ident"], link, *FAST)
    assert res.exit_code == 2 and f"{link} is given twice (as {flights['ident']})" in res.output


def test_validating_on_a_session_identified_from_is_warned_of(flights, caplog) -> None:
    caplog.set_level(logging.WARNING)
    res = run("identify", flights["ident"], *FAST, "--validate", flights["ident"])
    assert res.exit_code == 0, res.output
    assert f"--validate {flights['ident']} is also identified from" in caplog.text
    caplog.clear()
    res = run("identify", flights["ident"], *FAST, "--validate", flights["same"])
    assert "also identified from" not in caplog.text


def test_identify_prints_the_fit_compare_prints(flights, tmp_path) -> None:
    """One rule for the windows: `identify --validate V` and `compare MODEL V` gave two fits
    on V (1.07 s and 2 s windows: -43 % against -83 % on a CrazyPAD log)."""
    out = tmp_path / "m.h5"
    res = run("identify", flights["ident"], *FAST, "--validate", flights["same"], "--out", out,
              "--json")
    assert res.exit_code == 0, res.output
    ident = json.loads(res.stdout)["validation"][0]
    res = run("compare", out, flights["same"], "--json")
    assert res.exit_code == 0, res.output
    mode = json.loads(res.stdout)["modes"][0]
    assert ident["mode"] == f"validation: {mode['mode']}"
    assert ident["fit_percent"] == pytest.approx(mode["overall"])
