"""``groundstation import`` on log variants the other importer tests do not write: a CSV saved
again by a spreadsheet (BOM, CRLF, blank lines), a CSV whose times are no Crazyflie tick, a uSD
log cut inside its first bytes, and a log imported into its own folder with ``--force``."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main as gs
from tests.importers.test_robustness import usd_with_variables


def _import(*args) -> object:
    return CliRunner().invoke(gs, ["import", *map(str, args)])


def _one_line_error(res) -> str:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and res.stderr.count("\n") == 1, res.output
    return res.stderr.strip()


def test_a_csv_saved_with_a_bom_and_crlf_imports_as_written(tmp_path):
    """A cfclient CSV opened and saved by a spreadsheet starts with a UTF-8 BOM: it was refused
    as "neither a uSD-card deck log nor a cfclient CSV"."""
    f = tmp_path / "Gyro-20240101T10-00-00.csv"
    f.write_bytes(b"\xef\xbb\xbfTimestamp,gyro.x,gyro.y\r\n100,1.5,-2\r\n110,2.5,-3\r\n")
    res = _import(f, "--out", tmp_path / "o")
    assert res.exit_code == 0, res.output
    st = open_session(tmp_path / "o" / f"{tmp_path.name}.h5")["Gyro"]
    assert st.value_fields == ["x", "y"] and st.sources["x"] == "gyro.x"
    np.testing.assert_array_equal(st.values(), [[1.5, -2], [2.5, -3]])
    np.testing.assert_array_equal(st.time, [0.1, 0.11])


def test_errors_name_the_file_s_line_when_blank_lines_precede_it(tmp_path):
    """Blank lines were left out of the count: "fix or delete line 3" named another line."""
    f = tmp_path / "a.csv"
    f.write_text("Timestamp,acc.z\n\n100,1\n\n110,oops\n120,3\n")
    assert "line 5 has the non-number 'oops'" in _one_line_error(_import(f, "--out",
                                                                         tmp_path / "o"))
    f.write_text("Timestamp,acc.z\n\n100,1\n\n110,2\n90,3\n")
    line = _one_line_error(_import(f, "--out", tmp_path / "o"))
    assert "line 6: Timestamp 90 ms goes back from 110 ms on line 5" in line
    f.write_text("Timestamp,acc.z\n100,1\n\n110,2\n\n120\n\n")  # cut short: still the last
    res = _import(f, "--out", tmp_path / "o")
    assert res.exit_code == 0, res.output
    [problem] = open_session(tmp_path / "o" / f"{tmp_path.name}.h5").problems
    assert "a.csv: last line 6 is incomplete" in problem
    f.write_text("Timestamp,acc.z\n100,1\n110,2,7\n")  # a last line too long is no cut
    assert "line 3 has 3 columns (or empty ones), the header 2" in _one_line_error(
        _import(f, "--out", tmp_path / "o2"))


def test_a_timestamp_beyond_the_crazyflie_tick_is_one_line(tmp_path):
    """``1e30`` passed as whole milliseconds: numpy warned about an invalid cast on stderr and
    the session held a made-up firmware tick."""
    f = tmp_path / "a.csv"
    f.write_text("Timestamp,acc.z\n1e30,1\n2e30,2\n")
    line = _one_line_error(_import(f, "--out", tmp_path / "o"))
    assert "a.csv: Timestamp must be whole milliseconds from 0 to 4294967295" in line
    assert not (tmp_path / "o").exists() or not list((tmp_path / "o").iterdir())


def test_a_usd_log_cut_inside_its_first_bytes_says_so(tmp_path):
    """A copy of a few bytes starting 0xBC was "not a uSD-card deck log (no 0xBC header
    byte)"."""
    src = tmp_path / "log09"
    src.write_bytes(b"\xbc\x02\x00\x01")
    line = _one_line_error(_import(src, "--out", tmp_path / "o"))
    assert "log09: only 4 bytes, cut short inside its header" in line and "0xBC" not in line


def test_force_never_replaces_the_log_being_imported(tmp_path):
    """A log named ``log00.h5`` imported into its own folder with ``--force`` was replaced by
    its session: the recorded log was gone."""
    src = tmp_path / "log00.h5"
    src.write_bytes(usd_with_variables([b"a.x"]))
    before = src.read_bytes()
    line = _one_line_error(_import(src, "--out", tmp_path, "--force"))
    assert "log00.h5: is the log being imported" in line and "another --out" in line
    assert src.read_bytes() == before and sorted(p.name for p in tmp_path.iterdir()) == \
        ["log00.h5"]
    assert _import(src, "--out", tmp_path / "o", "--force").exit_code == 0


def test_a_block_that_logged_nothing_keeps_no_other_block_out(tmp_path):
    """cfclient writes a block's header when logging starts: a block that never delivered was
    "header only, no samples" and refused the whole flight, the other blocks' data with it."""
    folder = tmp_path / "20240101T10-00-00"
    folder.mkdir()
    (folder / "Gyro-20240101T10-00-00.csv").write_text("Timestamp,gyro.x\n100,1\n110,2\n")
    empty = folder / "Motors-20240101T10-00-00.csv"
    empty.write_text("Timestamp,motor.m1\n")
    res = _import(folder, "--out", tmp_path / "o")
    assert res.exit_code == 0, res.output
    s = open_session(tmp_path / "o" / f"{folder.name}.h5")
    np.testing.assert_array_equal(s["Gyro"].values(), [[1], [2]])
    assert "Motors" not in s.streams
    assert s.problems == ["imported log: Motors-20240101T10-00-00.csv: header only, no samples "
                          "(the block logged nothing); no stream"]
    line = _one_line_error(_import(empty, "--out", tmp_path / "p"))  # nothing else: refused
    assert line.endswith("Motors-20240101T10-00-00.csv: header only, no samples; nothing to "
                         "import")
    assert not (tmp_path / "p").exists() or not list((tmp_path / "p").iterdir())
