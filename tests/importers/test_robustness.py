"""``groundstation import`` on damaged input: one line naming the file and row, exit 2, no
traceback, nothing written; the damaged-log hint names the command-line flag."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main as gs
from tests.importers.test_import import usd_bytes, write_csv


def _one_line_error(res) -> str:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and res.stderr.count("\n") == 1, res.output
    return res.stderr.strip()


def test_csv_timestamps_going_backwards_are_refused(tmp_path):
    src = tmp_path / "flight"
    src.mkdir()
    f = write_csv(src / "Gyro-20240101T10-00-00.csv", ["Timestamp", "gyro.x"],
                  [[100, 1], [110, 2], [105, 3], [120, 4]])
    before = f.read_bytes()
    line = _one_line_error(CliRunner().invoke(gs, ["import", str(src), "--out",
                                                   str(tmp_path / "o")]))
    assert "line 4" in line and "goes back" in line and "Gyro-" in line
    assert f.read_bytes() == before and not list((tmp_path / "o").glob("*.h5"))


def test_csv_24_bit_wrap_is_not_going_backwards(tmp_path):
    wrap = 1 << 24
    f = write_csv(tmp_path / "a.csv", ["Timestamp", "gyro.x"],
                  [[wrap - 20, 1], [wrap - 10, 2], [0, 3], [10, 4]])
    res = CliRunner().invoke(gs, ["import", str(f), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize("bad", ["nan", "inf", "-inf", "NaN"])
@pytest.mark.parametrize("column", [0, 1])
def test_csv_non_finite_values_are_refused(tmp_path, bad, column):
    rows = [[100, 1.5], [110, 2.5], [120, 3.5]]
    rows[1][column] = bad
    f = write_csv(tmp_path / "Acc-20240101T10-00-00.csv", ["Timestamp", "acc.z"], rows)
    line = _one_line_error(CliRunner().invoke(gs, ["import", str(f), "--out",
                                                   str(tmp_path / "o")]))
    assert "line 3" in line and "non-finite" in line
    assert ("Timestamp" if column == 0 else "acc.z") in line
    assert not list((tmp_path / "o").glob("*.h5"))


def test_damaged_usd_log_names_the_cli_flag(tmp_path):
    n = 10
    data = bytearray(usd_bytes(stamps_us=1000 * np.arange(n), a=np.zeros(n, np.float32),
                               b=np.zeros(n, np.uint16)))
    data[-1] ^= 0xFF  # CRC mismatch
    src = tmp_path / "log03"
    src.write_bytes(bytes(data))
    line = _one_line_error(CliRunner().invoke(gs, ["import", str(src), "--out",
                                                   str(tmp_path / "o")]))
    assert "--allow-damaged" in line and "pass allow_damaged=True" not in line
    ok = CliRunner().invoke(gs, ["import", str(src), "--allow-damaged", "--out",
                                 str(tmp_path / "o")])
    assert ok.exit_code == 0, ok.output
