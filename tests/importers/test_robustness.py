"""``groundstation import`` on damaged input: one line naming the file and row, exit 2, no
traceback, nothing written; the damaged-log hint names the command-line flag."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from cfsession import SessionWriter, open_session
from groundstation.cli import main as gs
from tests.importers.test_import import usd_bytes, write_csv
from tests.importers.usd_logs import build_usd


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


def _import(*args: str):
    return CliRunner().invoke(gs, ["import", *args])


@pytest.mark.parametrize(("header", "fields"), [
    (["a.x", "b.x", "a_x"], ["a_x", "b_x", "a_x_2"]),
    (["g.host_time", "g.fw_time_ms", "host_time"], ["g_host_time", "g_fw_time_ms", "host_time_2"]),
    (["motor.m1", "m.ä-b"], ["m1", "__b"]),
])
def test_csv_field_names_are_unique_after_mangling(tmp_path, header, fields):
    rows = [[10 * i, *(i * 10 + j for j in range(len(header)))] for i in range(1, 4)]
    f = write_csv(tmp_path / "Blk-20240101T10-00-00.csv", ["Timestamp", *header], rows)
    res = _import(str(f), "--out", str(tmp_path / "o"))
    assert res.exit_code == 0, res.output
    st = open_session(tmp_path / "o" / f"{tmp_path.name}.h5")["Blk"]
    assert st.value_fields == fields
    assert [st.sources[f] for f in fields] == header  # the full variable names are kept
    np.testing.assert_array_equal(st.values(), np.array(rows)[:, 1:])


@pytest.mark.parametrize(("header", "says"), [
    (["g."], "variable 1 'g.' has an empty name after its group"),
    (["a.b", ""], "variable 2 has an empty name"),
    (["a.b", "a.b"], "variable 2 'a.b' appears twice (also variable 1)"),
    (["a.b", "x" * 65], "is longer than 64 characters"),
    ([f"g.v{i}" for i in range(513)], "513 variables; at most 512"),
    ([f"g.v{i}" for i in range(60_000)], "60000 variables; at most 512"),
])
def test_csv_bad_headers_are_one_line_errors(tmp_path, header, says):
    f = write_csv(tmp_path / "a.csv", ["Timestamp", *header], [[10, *range(len(header))]])
    line = _one_line_error(_import(str(f), "--out", str(tmp_path / "o")))
    assert says in line and "a.csv: header" in line
    assert not (tmp_path / "o").exists() or not list((tmp_path / "o").iterdir())


def test_512_variables_of_64_characters_fit(tmp_path):
    header = [f"g{i:03d}." + "v" * 59 for i in range(512)]
    assert {len(h) for h in header} == {64}
    rows = [[10, *range(512)], [20, *range(512)]]
    f = write_csv(tmp_path / "a.csv", ["Timestamp", *header], rows)
    res = _import(str(f), "--out", str(tmp_path / "o"))
    assert res.exit_code == 0, res.output
    st = open_session(tmp_path / "o" / f"{tmp_path.name}.h5")["a"]
    assert len(st.value_fields) == 512 and st.values()[1, 511] == 511


def usd_with_variables(entries: list[bytes]) -> bytes:
    """A format-2 uSD log with one event (id 1) of uint8 variables and two records."""
    return build_usd(version=2, events=[(1, "fixedFrequency", [(e, "B") for e in entries])],
                     records=[(1, 1000 * k, bytes((k + j) % 256 for j in range(len(entries))))
                              for k in range(2)])


def test_usd_names_are_mangled_like_csv_names(tmp_path):
    src = tmp_path / "log01"
    src.write_bytes(usd_with_variables([b"a.x", b"b.x", b"a_x", b"g.host_time"]))
    res = _import(str(src), "--out", str(tmp_path / "o"))
    assert res.exit_code == 0, res.output
    st = open_session(tmp_path / "o" / "log01.h5")["a+b+a_x+g"]
    assert st.value_fields == ["a_x", "b_x", "a_x_2", "g_host_time"]
    np.testing.assert_array_equal(st.values()[1], [1, 2, 3, 4])


@pytest.mark.parametrize(("entries", "says"), [
    ([b"g."], "empty name after its group"),
    ([b"a.x", b"a.x"], "'a.x' appears twice"),
    ([b"g.v%d" % i for i in range(600)], "600 variables; at most 512"),
])
def test_usd_bad_variable_names_are_one_line_errors(tmp_path, entries, says):
    src = tmp_path / "log02"
    src.write_bytes(usd_with_variables(entries))
    line = _one_line_error(_import(str(src), "--out", str(tmp_path / "o")))
    assert says in line and "log02: event 'fixedFrequency'" in line


def test_a_failed_write_leaves_no_file_and_force_replaces(tmp_path, monkeypatch):
    src = tmp_path / "log04"
    src.write_bytes(usd_with_variables([b"a.x"]))
    out = tmp_path / "o"
    assert _import(str(src), "--out", str(out)).exit_code == 0
    before = (out / "log04.h5").read_bytes()

    def disk_full(self, stream, rows):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(SessionWriter, "extend", disk_full)
    line = _one_line_error(_import(str(src), "--out", str(out), "--force"))
    assert "log04.h5: cannot write the session" in line and "No space left" in line
    assert sorted(p.name for p in out.iterdir()) == ["log04.h5"]  # no temporary left
    assert (out / "log04.h5").read_bytes() == before  # the old file kept whole
    monkeypatch.undo()
    src.write_bytes(usd_with_variables([b"b.y", b"b.z"]))
    assert "already exists; pass --force" in _one_line_error(_import(str(src), "--out", str(out)))
    assert _import(str(src), "--out", str(out), "--force").exit_code == 0
    assert open_session(out / "log04.h5")["b"].value_fields == ["y", "z"]


def test_a_symlink_at_the_output_is_never_followed(tmp_path):
    src = tmp_path / "log05"
    src.write_bytes(usd_with_variables([b"a.x"]))
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    out = tmp_path / "o"
    out.mkdir()
    (out / "log05.h5").symlink_to(victim)
    assert "already exists" in _one_line_error(_import(str(src), "--out", str(out)))
    assert _import(str(src), "--out", str(out), "--force").exit_code == 0
    assert victim.read_text() == "keep me" and not (out / "log05.h5").is_symlink()


def test_an_export_folder_is_named_as_one(tmp_path):
    """Importing this tool's own CSV export said only "holds no uSD-card deck logs or cfclient
    CSVs" (first-day review)."""
    from tests.viz.sessions import write_session

    session = write_session(tmp_path / "f.h5")
    assert CliRunner().invoke(gs, ["export", str(session), "--to", "csv", "--out",
                                   str(tmp_path / "csv")]).exit_code == 0
    res = CliRunner().invoke(gs, ["import", str(tmp_path / "csv"), "--out",
                                  str(tmp_path / "out")])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "a 'groundstation export --to csv' folder, not a log to import" in res.output


def test_a_folder_of_sessions_is_named_as_one(tmp_path):
    from tests.viz.sessions import write_session

    write_session(tmp_path / "flights" / "f.h5")
    res = CliRunner().invoke(gs, ["import", str(tmp_path / "flights"), "--out",
                                  str(tmp_path / "out")])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "its 1 .h5 file(s) are sessions already" in res.output


def test_a_session_file_given_to_import_is_named_as_one(tmp_path):
    """`import flight.h5` said "neither a uSD-card deck log nor a cfclient CSV", as for any
    unknown file (first-day review)."""
    from tests.viz.sessions import write_session

    session = write_session(tmp_path / "f.h5")
    res = CliRunner().invoke(gs, ["import", str(session), "--out", str(tmp_path / "out")])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert f"{session}: an HDF5 file (a session or a model" in res.output
    assert "groundstation info reads a session as it is" in res.output
