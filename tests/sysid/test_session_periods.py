"""Sessions identified or validated together are put on one grid period.

Each session's grid period defaults to its logged period, which an imported log measures from
its own timestamps: the two real CrazyPAD flights of one vehicle and logger read 0.0098859 s and
0.0098861 s, and every command refused them together ("data[2] has dt=..."; a sweep ran its
whole grid before it said so). Periods within ``PERIOD_MATCH`` (1 %) are one period; beyond
it the files and their periods are one line that says to pass ``--dt``.
"""

from __future__ import annotations

import h5py
import pytest
from click.testing import CliRunner

from groundstation.importers import usd_to_session
from sysid.cli import main
from sysid.session_io import PERIOD_MATCH, load_sessions
from tests.paths import CRAZYPAD, needs_crazypad
from tests.sysid.flights import DT, known_system, write_flight

INPUTS = ",".join(f"controller.cmd_{a}" for a in ("thrust", "roll", "pitch", "yaw"))
OUTPUTS = ",".join([*(f"controller.r_{a}" for a in ("roll", "pitch", "yaw")),
                    "controller.accelz"])
FAST = ["--order", "4", "--past", "10", "--future", "5"]


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@needs_crazypad
def test_two_real_flights_of_one_logger_identify_together(tmp_path):
    paths = [usd_to_session(source=CRAZYPAD / name, out=tmp_path / f"{name}.h5")
             for name in ("controller_E8_log00", "controller_E8_log01")]
    alone = [load_sessions([p], inputs=INPUTS.split(","), outputs=OUTPUTS.split(","))[0]
             for p in paths]
    periods = [group[0].dt for group in alone]
    assert periods[0] != periods[1] and abs(periods[1] / periods[0] - 1) < 1e-4
    together = load_sessions(paths, inputs=INPUTS.split(","), outputs=OUTPUTS.split(","))
    assert {d.dt for group in together for d in group} == {periods[0]}
    assert [len(g) for g in together] == [len(g) for g in alone] == [2, 2]
    res = _run("identify", *paths, "--inputs", INPUTS, "--outputs", OUTPUTS, *FAST)
    assert res.exit_code == 0, res.output
    assert "4 experiments" in res.output or "4 experiment(s)" in res.output, res.output
    res = _run("sweep", paths[0], "--validate", paths[1], "--inputs", INPUTS, "--outputs",
               OUTPUTS, "--pasts", "10", "--futures", "5", "--orders", "4")
    assert res.exit_code == 0, res.output
    assert "failed" not in res.output


def _declare_period(path, period_s: float) -> None:
    with h5py.File(path, "a") as f:
        for name in ("motors", "acc", "gyro"):
            f[name].attrs["period_s"] = period_s


@pytest.fixture(scope="module")
def pair(tmp_path_factory):
    d = tmp_path_factory.mktemp("periods")
    return [write_flight(d / f"f{k}.h5", system=known_system(), seed=k, n=800).path
            for k in range(2)]


def test_periods_within_the_match_are_one_grid_beyond_it_one_line(pair, tmp_path):
    near, far = tmp_path / "near.h5", tmp_path / "far.h5"
    for dst, factor in ((near, 1 + PERIOD_MATCH / 2), (far, 1 + 2 * PERIOD_MATCH)):
        dst.write_bytes(pair[1].read_bytes())
        _declare_period(dst, DT * factor)
    assert _run("identify", pair[0], near, *FAST).exit_code == 0
    res = _run("identify", pair[0], far, *FAST)
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert f"({pair[0].name} {DT:g} s, far.h5 {DT * (1 + 2 * PERIOD_MATCH):g} s)" in res.output
    assert "--dt" in res.output
    assert _run("identify", pair[0], far, *FAST, "--dt", DT).exit_code == 0
