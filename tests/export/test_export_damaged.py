"""``groundstation export`` of a damaged or crash-truncated session: exported as far as it
reads, each problem ``groundstation info`` lists repeated once as a warning naming the file,
whatever the format (``mat`` reads u and y through sysid's reader, which warns for it)."""

from __future__ import annotations

import logging
import shutil

import h5py
import pytest
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main
from tests.sysid.flights import known_system, write_flight
from tests.sysid.test_damaged_sessions import damage_chunk


@pytest.fixture(scope="module")
def damaged(tmp_path_factory):
    d = tmp_path_factory.mktemp("export-damaged")
    good = write_flight(d / "good.h5", system=known_system(), seed=4, n=1500).path
    bad = d / "bad.h5"
    shutil.copy(good, bad)
    damage_chunk(bad, chunk=10)
    with h5py.File(bad, "r+") as f:  # and its writer died
        f.attrs["closed_cleanly"] = 0
    problems = open_session(bad).problems
    assert len(problems) == 2 and any("unreadable" in p for p in problems)
    return bad, problems


@pytest.mark.parametrize("to", ["csv", "mat", "parquet"])
def test_each_problem_is_one_warning_naming_the_file(damaged, to, tmp_path, caplog):
    if to == "parquet":
        pytest.importorskip("pyarrow")
    bad, problems = damaged
    out = tmp_path / ("bad.mat" if to == "mat" else "out")
    with caplog.at_level(logging.WARNING):
        res = CliRunner().invoke(main, ["export", str(bad), "--to", to, "--out", str(out)])
    assert res.exit_code == 0, res.output
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING
              and ": problem: " in r.getMessage()]
    assert warned == [f"{bad}: problem: {p}" for p in problems]
    assert out.exists()
