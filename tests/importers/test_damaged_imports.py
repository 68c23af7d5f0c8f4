"""``groundstation import --allow-damaged``: what is said about a damaged log is true, and it
stays with the session. A uSD log's CRC covers the whole file and cannot locate the damage, so
every record is kept as read; only damage the record layout locates (a last record cut short,
a record of no declared event) drops records. Each problem is a warning on stderr, a warning
event, and a problem of the session (``Session.problems``: ``info`` and ``sysid`` see it)."""

from __future__ import annotations

import json
import logging
import struct

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main as gs
from sysid.session_io import load_experiments
from tests.importers.test_import import cfclient_folder, usd_bytes

N = 40
RECORD = struct.calcsize("<HQfH")  # event id, µs stamp, acc.x, motor.m1


def _log() -> tuple[bytearray, int, np.ndarray]:
    """A format-2 uSD log, the byte offset of its first record and its acc.x values."""
    acc = np.float32(np.linspace(1, 2, N))
    data = bytearray(usd_bytes(stamps_us=10_000 * np.arange(N), a=acc,
                               b=np.arange(N, dtype=np.uint16)))
    first = len(data) - 4 - N * RECORD
    return data, first, acc


def _import(tmp_path, data: bytes, caplog) -> tuple[object, list[str]]:
    src = tmp_path / "log05"
    src.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING, logger="groundstation.importers.usd"):
        res = CliRunner().invoke(gs, ["import", str(src), "--allow-damaged", "--out",
                                      str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    warned = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING
              and r.name == "groundstation.importers.usd"]
    return open_session(tmp_path / "o" / "log05.h5"), warned


def _damage_events(session) -> list[str]:
    return [e.text for e in session.events() if e.level == "warning"]


def test_a_crc_mismatch_keeps_every_record_as_read_and_says_so(tmp_path, caplog):
    data, first, acc = _log()
    data[first + 7 * RECORD + 10: first + 7 * RECORD + 14] = b"\0\0\0\0"  # acc.x of record 7
    s, warned = _import(tmp_path, data, caplog)
    x = s["acc+motor"].data["x"]
    assert len(x) == N and x[7] == 0.0  # kept as read: the zeroed value is in the data
    np.testing.assert_array_equal(np.delete(x, 7), np.delete(acc, 7))
    [said] = warned
    assert str(tmp_path / "log05") in said and "CRC mismatch" in said
    assert "cannot say where" in said and "every record that decodes is kept as read" in said
    assert "dropped" not in said and "dropped" not in s.meta["source_format"]
    problem = said.split(": ", 1)[1]
    assert s.problems == [f"imported log: {problem}"]
    assert json.loads(s.meta["source_problems"]) == [problem]
    assert _damage_events(s) == [f"damaged source: {problem}"]
    info = CliRunner().invoke(gs, ["info", str(s.path)])
    assert f"problem: imported log: {problem}" in info.stdout
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="sysid.session_io"):
        load_experiments(s.path, inputs=["motor"], outputs=["acc"], window=None)
    assert f"{s.path}: problem: imported log: {problem}" in caplog.messages


def test_a_last_record_cut_short_is_dropped_and_said(tmp_path, caplog):
    data, first, _ = _log()
    s, warned = _import(tmp_path, data[:-10], caplog)  # the card pulled while writing
    assert len(s["acc+motor"]) == N - 1
    cut = first + (N - 1) * RECORD
    assert len(warned) == 2 and "no CRC trailer: the file ends inside a record" in warned[0]
    assert warned[1].endswith(f"last record truncated at byte {cut}; dropped, the records "
                              "before it kept")
    assert s.problems == [f"imported log: {w.split(': ', 1)[1]}" for w in warned]
    assert len(_damage_events(s)) == 2


def test_a_log_cut_before_its_crc_keeps_every_record_and_says_so(tmp_path, caplog):
    """Power lost while logging: the deck had not written its CRC (it does when logging
    stops). The last record, whose last 4 bytes were taken as the CRC, was dropped."""
    data, _, acc = _log()
    s, warned = _import(tmp_path, data[:-4], caplog)
    np.testing.assert_array_equal(s["acc+motor"].data["x"], acc)  # all N rows
    [said] = warned
    problem = said.split(": ", 1)[1]
    assert problem == ("no CRC trailer: the file ends after a complete record, cut before the "
                       "deck wrote its CRC (it does when logging is stopped; power lost or the "
                       "card pulled while logging?); nothing can be checked, every complete "
                       "record is kept as read")
    assert s.problems == [f"imported log: {problem}"] and s.meta["crc_ok"] == 0
    assert s.meta["source_format"].endswith("(NO CRC, cut before the deck wrote it)")
    info = CliRunner().invoke(gs, ["info", str(s.path)])
    assert f"problem: imported log: {problem}" in " ".join(info.stdout.split())


def test_a_record_of_no_declared_event_drops_the_rest_and_says_so(tmp_path, caplog):
    data, first, _ = _log()
    at = first + 5 * RECORD
    data[at: at + 2] = struct.pack("<H", 99)
    s, warned = _import(tmp_path, data, caplog)
    assert len(s["acc+motor"]) == 5
    rest = N * RECORD - 5 * RECORD
    assert warned[1].endswith(f"record at byte {at} has unknown event id 99; the {rest} bytes "
                              "from there dropped, the records before it kept")
    assert s.problems[1] == f"imported log: {warned[1].split(': ', 1)[1]}"


def test_a_csv_line_cut_short_is_a_problem_of_the_session(tmp_path):
    folder, ms, *_ = cfclient_folder(tmp_path)
    gyro = next(folder.glob("Gyro-*.csv"))
    with open(gyro, "a") as fh:
        fh.write("123,")  # the client killed while writing
    res = CliRunner().invoke(gs, ["import", str(folder), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    s = open_session(tmp_path / "o" / f"{folder.name}.h5")
    assert len(s["Gyro"]) == len(ms)
    assert s.problems == [f"imported log: {gyro.name}: last line {len(ms) + 2} is incomplete "
                          "(client killed?); dropped"]


def test_an_intact_import_has_no_problems(tmp_path, caplog):
    data, _, _ = _log()
    s, warned = _import(tmp_path, data, caplog)
    assert warned == [] and s.problems == [] and "source_problems" not in s.meta
    assert _damage_events(s) == [] and "(CRC ok)" in s.meta["source_format"]


@pytest.mark.parametrize("attrs, says", [
    ({"crc_ok": 0}, "its CRC did not match (imported with --allow-damaged)"),
    ({"source_problems": "{not json"}, "root attribute 'source_problems' is damaged"),
    ({"source_problems": json.dumps([1, 2])}, "root attribute 'source_problems' is damaged"),
    ({"source_problems": json.dumps([f"p{i}" for i in range(25)])}, "5 more problems"),
])
def test_the_reader_lists_an_imported_log_s_damage(tmp_path, caplog, attrs, says):
    """Also a uSD import from before ``source_problems`` (``crc_ok`` 0 only) and a damaged or
    hostile attribute: listed, never a traceback."""
    data, _, _ = _log()
    s, _ = _import(tmp_path, data, caplog)
    with h5py.File(s.path, "r+") as f:
        for key, value in attrs.items():
            f.attrs[key] = value
    problems = open_session(s.path).problems
    assert any(p.startswith("imported log: ") and says in p for p in problems), problems
    assert len(problems) <= 21


@pytest.mark.parametrize("allow", [False, True])
def test_a_log_cut_inside_its_header_says_nothing_can_be_salvaged(tmp_path, allow):
    """Cut inside the header the CRC mismatches too; its advice (--allow-damaged) then led to
    a second error: the header's truncation is said first, with no advice that cannot work."""
    data, first, _ = _log()
    src = tmp_path / "log06"
    src.write_bytes(bytes(data[:first - 3]))
    res = CliRunner().invoke(gs, ["import", str(src), "--out", str(tmp_path / "o"),
                                  *(["--allow-damaged"] if allow else [])])
    assert res.exit_code == 2
    line = res.output.strip().splitlines()[-1]
    assert line.startswith(f"error: {src}: header truncated"), line
    assert line.endswith("(the file ends before its first record: nothing to import or "
                         "salvage)")
    assert "--allow-damaged" not in res.output


@pytest.mark.parametrize("allow", [False, True])
def test_a_log_cut_after_its_header_says_nothing_can_be_salvaged(tmp_path, allow):
    """Power lost before the first record: a whole header and no CRC, nothing to import."""
    data, first, _ = _log()
    src = tmp_path / "log07"
    src.write_bytes(bytes(data[:first]))
    res = CliRunner().invoke(gs, ["import", str(src), "--out", str(tmp_path / "o"),
                                  *(["--allow-damaged"] if allow else [])])
    assert res.exit_code == 2
    line = res.output.strip().splitlines()[-1]
    assert line.endswith("nothing to import (every log block is empty)" if allow else
                         "no CRC trailer: the file ends after its header, cut before the deck "
                         "wrote its CRC (it does when logging is stopped; power lost or the "
                         "card pulled while logging?): no record, nothing to import or "
                         "salvage"), line
