"""A finished session keeps the permission bits it was created with (the umask's): the
compressing rewrite on close goes through ``mkstemp`` (owner-only) and must not leave its mode."""

from __future__ import annotations

import os
import stat
from contextlib import contextmanager

import pytest
from click.testing import CliRunner

from cfsession import SessionWriter, open_session
from cfsession.schema import log_block_spec
from cfsession.writer import standard_streams
from groundstation.cli import main as gs
from groundstation.recorder import Recorder

GYRO = log_block_spec(name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"],
                      period_s=0.02)


def _rows(n: int) -> list[tuple]:
    return [(0.02 * k, 1000 + 20 * k, 0.1, 0.2, 0.3) for k in range(n)]


@contextmanager
def _umask(mask: int):
    old = os.umask(mask)
    try:
        yield
    finally:
        os.umask(old)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


@pytest.mark.parametrize(("mask", "mode"), [(0o022, 0o644), (0o027, 0o640), (0o077, 0o600)])
@pytest.mark.parametrize("compress", [True, False])
def test_a_closed_session_has_the_umasks_mode(tmp_path, mask, mode, compress):
    out = tmp_path / "s.h5"
    with _umask(mask), SessionWriter(out, streams=[GYRO, *standard_streams()],
                                     compress_on_close=compress) as w:
        w.extend("gyro", _rows(50))
    assert _mode(out) == mode
    assert len(open_session(out)["gyro"]) == 50
    assert [p.name for p in tmp_path.iterdir()] == ["s.h5"]  # no rewrite left behind


def test_a_recorded_flight_has_the_umasks_mode(tmp_path):
    with _umask(0o022):
        rec = Recorder(tmp_path / "flight.h5")
        rec.begin(streams=[GYRO, *standard_streams()], metadata={})
        rec.rows("gyro", _rows(50))
        rec.end(summary={"duration_s": 1.0})
    assert _mode(rec.path) == 0o644


def test_an_imported_session_has_the_umasks_mode(tmp_path):
    log = tmp_path / "Gyro-20240101T10-00-00.csv"
    log.write_text("Timestamp,gyro.x\n" + "".join(f"{10 * k},{k}\n" for k in range(50)))
    with _umask(0o022):
        res = CliRunner().invoke(gs, ["import", str(log), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    [made] = (tmp_path / "out").iterdir()
    assert _mode(made) == 0o644
