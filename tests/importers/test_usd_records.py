"""The uSD reader's numpy decoding against the straightforward per-record parse
(``tests/importers/usd_logs.py``), and what it does with time that goes back."""

from __future__ import annotations

import logging
import random
import struct
import zlib

import numpy as np
import pytest
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main as gs
from groundstation.importers import UsdFormatError, read_usd
from tests.importers.usd_logs import (
    ALL_TYPES,
    build_usd,
    reference_read,
    same_values,
    usd_header,
)

ONE_SIZE = [ALL_TYPES[0], (8, "twin", [(f"t.v{i}", "f") for i in range(5)])]
"""Two events whose records have one size (20 bytes of values): the starts are found at once."""
_VALUE_BYTES = {7: 20, 8: 20, 9: 2, 300: 0}
_SPECIAL = [b"\x01\x00\x80\x7f", b"\x01\x00\xc0\xff", b"\x00\x00\x80\xff", b"\x00\x00\x00\x80"]
"""float32 bit patterns: a signalling NaN, a negative quiet NaN with a payload, -inf, -0.0."""


def _records(*, events, n: int, seed: int, runs: bool = False) -> list[tuple[int, int, bytes]]:
    """``n`` records of random events in ``events`` (ids from ``_VALUE_BYTES``; with ``runs``,
    one event for 50 records on average) with random value bytes (any bit pattern: signalling
    NaNs of both float widths included), rising timestamps."""
    rng = random.Random(seed)
    ids = [e[0] for e in events if e[0] != 4]  # event 4 ('never') stays without records
    out, event_id = [], ids[0]
    for k in range(n):
        if not runs or rng.random() < 0.02:
            event_id = rng.choice(ids)
        raw = bytearray(rng.getrandbits(8) for _ in range(_VALUE_BYTES[event_id]))
        if event_id in (7, 8) and k % 5 == 0:
            at = 14 if event_id == 7 else 4 * rng.randrange(5)  # event 7's g.f is at 14
            raw[at:at + 4] = rng.choice(_SPECIAL)
        if event_id == 9 and k % 3 == 0:
            raw[:] = rng.choice([b"\x01\x7c", b"\xff\xfd", b"\x00\x7e"])  # half NaNs
        out.append((event_id, 1000 + 7 * k, bytes(raw)))
    return out


def _assert_as_reference(data: bytes, log) -> None:
    """Every event's timestamps and values, dtypes and bytes, as the reference reads them."""
    ref = reference_read(data)
    assert list(log.events) == list(ref)
    scale = 1e-3 if log.version == 1 else 1e-6
    for name, (stamps, values) in ref.items():
        ev = log.events[name]
        assert ev.timestamps_s.dtype == np.float64
        np.testing.assert_array_equal(ev.timestamps_s, stamps.astype(np.float64) * scale)
        assert list(ev.values) == list(values)
        for var, col in values.items():
            assert same_values(ev.values[var], col), (name, var)


@pytest.mark.parametrize("version", [1, 2])
@pytest.mark.parametrize(("events", "runs"), [(ALL_TYPES, False), (ALL_TYPES, True),
                                              (ONE_SIZE, False)],
                         ids=["sizes-interleaved", "sizes-in-runs", "one-size"])
def test_arrays_equal_the_per_record_reference(tmp_path, version, events, runs):
    """Every type letter, events of three record sizes (interleaved record by record, or in
    runs), one with no variables, one declared with no records; any bit pattern, a signalling
    NaN quieted as a Python float does."""
    records = _records(events=events, n=3000, seed=1, runs=runs)
    data = build_usd(version=version, events=events, records=records)
    (tmp_path / "log").write_bytes(data)
    log = read_usd(tmp_path / "log")
    assert log.crc_ok and log.problems == []
    _assert_as_reference(data, log)
    assert {len(e.timestamps_s) == 0 for e in log.events.values()} == (
        {False, True} if events is ALL_TYPES else {False})  # 'never' has no records


@pytest.mark.parametrize("events", [ALL_TYPES, ONE_SIZE], ids=["sizes-differ", "one-size"])
@pytest.mark.parametrize("cut", [1, 3, 11, 29])
def test_a_truncated_log_reads_as_the_reference_as_far_as_it_goes(tmp_path, events, cut):
    """Cut inside the last record's event id, timestamp or values (a valid CRC of what is
    left)."""
    records = [*_records(events=events, n=200, seed=2), (7, 99_999, bytes(range(20)))]
    whole = build_usd(version=2, events=events, records=records, crc=False)
    last = len(whole) - 30
    body = whole[:last + cut]
    data = body + struct.pack("<I", zlib.crc32(body))
    (tmp_path / "log").write_bytes(data)
    with pytest.raises(UsdFormatError, match=f"last record truncated at byte {last};"):
        read_usd(tmp_path / "log")
    log = read_usd(tmp_path / "log", allow_damaged=True)
    assert log.problems == [f"last record truncated at byte {last}; dropped, the records "
                            "before it kept"]
    _assert_as_reference(data, log)
    assert sum(len(e.timestamps_s) for e in log.events.values()) == len(records) - 1


def test_a_record_of_no_declared_event_stops_both_alike(tmp_path):
    records = _records(events=ALL_TYPES, n=100, seed=3, runs=True)
    body = bytearray(build_usd(version=1, events=ALL_TYPES, records=records, crc=False))
    at = len(usd_header(version=1, events=ALL_TYPES)) + sum(
        6 + _VALUE_BYTES[r[0]] for r in records[:40])
    body[at:at + 2] = struct.pack("<H", 5)
    data = bytes(body) + struct.pack("<I", zlib.crc32(body))
    (tmp_path / "log").write_bytes(data)
    log = read_usd(tmp_path / "log", allow_damaged=True)
    assert log.problems == [f"record at byte {at} has unknown event id 5; the "
                            f"{len(body) - at} bytes from there dropped, the records before "
                            "it kept"]
    _assert_as_reference(data, log)


FF = [(7, "fixedFrequency", [("g.a", "f"), ("g.b", "H"), ("g.c", "b")]), (9, "ev", [("x.e", "e")])]


def _ff(stamps: list[int], *, version: int) -> bytes:
    """Event 7 at ``stamps`` (7-byte values), one record of event 9 after its second."""
    recs = [(7, t, (float(k), k, -k)) for k, t in enumerate(stamps)]
    recs[2:2] = [(9, stamps[0], (0.5,))]
    return build_usd(version=version, events=FF, records=recs)


def test_the_32_bit_millisecond_tick_wrapping_around_is_undone(tmp_path):
    """Format 1 stamps the 32-bit ms tick (49.7 days): across 2**32 the time goes on."""
    top = 1 << 32
    stamps = [top - 25, top - 15, top - 5, 5, 15]
    (tmp_path / "log").write_bytes(_ff(stamps, version=1))
    log = read_usd(tmp_path / "log")
    assert log.problems == []
    np.testing.assert_array_equal(log.events["fixedFrequency"].timestamps_s,
                                  (top - 25 + 10 * np.arange(5)) / 1e3)


def test_a_damaged_stamp_near_the_top_is_no_wrap(tmp_path):
    """A stamp whose top byte is damaged, then the log goes on: the step back is said, and the
    rest of the log is not moved 49.7 days on as if the tick had wrapped."""
    stamps = [1000, 1010, 0xFF00_0000 + 1020, 1030, 1040]
    (tmp_path / "log").write_bytes(_ff(stamps, version=1))
    log = read_usd(tmp_path / "log")
    np.testing.assert_array_equal(log.events["fixedFrequency"].timestamps_s,
                                  np.array(stamps) / 1e3)
    [problem] = log.problems
    assert problem.startswith("event 'fixedFrequency' (block 'g'): time goes back at 1 of "
                              "its 4 steps, first at row 3 ")


def test_time_going_back_keeps_every_row_and_is_a_problem_info_lists(tmp_path, caplog):
    """A uSD event whose time goes back was imported silently (a cfclient CSV is refused):
    the rows are kept in file order and the session says where and by how much."""
    stamps = [1000, 2000, 3000, 2500, 4000, 1000, 5000]  # µs
    data = _ff(stamps, version=2)
    (tmp_path / "log08").write_bytes(data)
    with caplog.at_level(logging.WARNING, logger="groundstation.importers.usd"):
        res = CliRunner().invoke(gs, ["import", str(tmp_path / "log08"), "--out",
                                      str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    head = len(usd_header(version=2, events=FF))
    byte = head + 3 * (10 + 7) + (10 + 2)  # rows 0-2 of event 7 and event 9's one record
    text = (f"event 'fixedFrequency' (block 'g'): time goes back at 2 of its 6 steps, first at "
            f"row 3 "
            f"(from 0; byte {byte} of the file): 0.002500 s after 0.003000 s, 0.0005 s back; "
            "the largest 0.003 s back; every row kept, in file order")
    assert caplog.messages == [f"{tmp_path / 'log08'}: {text}"]  # a warning on stderr
    s = open_session(tmp_path / "o" / "log08.h5")
    assert s.problems == [f"imported log: {text}"]
    np.testing.assert_array_equal(s["g"].time, np.array(stamps) / 1e6)
    np.testing.assert_array_equal(s["g"].data["a"], np.arange(7, dtype=np.float32))
    info = CliRunner().invoke(gs, ["info", str(s.path)])
    assert f"problem: imported log: {text}" in " ".join(info.stdout.split())


@pytest.mark.parametrize("version", [1, 2])
def test_a_repeated_stamp_is_a_problem_in_format_2_only(tmp_path, caplog, version):
    """Format 2 stamps each record in µs as it is written (``usecTimestamp()``): two records
    of one event at one instant is damage, said as a cfclient CSV's repeated Timestamp is,
    every row kept. Format 1 stamps the 1 kHz tick: two records in one ms are how the deck logs
    at 1 kHz (or one event raised twice in a ms), said nowhere. A stamp another event shares
    (event 9's, row 0's) is no repeat."""
    stamps = [1000, 2000, 2000, 3000, 4000, 4000, 5000]  # µs (format 2) or ms (format 1)
    (tmp_path / "log09").write_bytes(_ff(stamps, version=version))
    with caplog.at_level(logging.WARNING, logger="groundstation.importers.usd"):
        res = CliRunner().invoke(gs, ["import", str(tmp_path / "log09"), "--out",
                                      str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    s = open_session(tmp_path / "o" / "log09.h5")
    np.testing.assert_array_equal(s["g"].time, np.array(stamps) * (1e-3 if version == 1 else
                                                                   1e-6))
    np.testing.assert_array_equal(s["g"].data["a"], np.arange(7, dtype=np.float32))
    if version == 1:
        assert caplog.messages == [] and s.problems == []
        return
    byte = len(usd_header(version=2, events=FF)) + 2 * (10 + 7) + (10 + 2)  # row 2 of event 7
    text = (f"event 'fixedFrequency' (block 'g'): 2 row(s) repeat the time of the row before, "
            f"first at row 2 (from 0; byte {byte} of the file): 0.002000 s; every row kept, "
            "the later row's values hold at that time")
    assert caplog.messages == [f"{tmp_path / 'log09'}: {text}"]  # a warning on stderr
    assert s.problems == [f"imported log: {text}"]
    info = CliRunner().invoke(gs, ["info", str(s.path)])
    assert f"problem: imported log: {text}" in " ".join(info.stdout.split())


_CUTS = (1, 2, 3, 4, 5, 9, 25)
"""Bytes of one more record (30 in format 2, 26 in format 1) the log is cut after: 4, as
many as a CRC (beginning with an event id, so a record cut short), up to one byte short."""


def _cut_log(version: int, case: str) -> tuple[list, bytes, bytes]:
    """Records of every event size, the last one of 'mark' (the shortest record); the intact
    log (trailer); and the log as ``case`` leaves it: ``intact``, ``bad-crc`` (a trailer that
    does not match), ``no-trailer`` (cut after the last record, before the deck wrote its
    CRC), ``cut-K`` (cut K bytes into one more record)."""
    records = [*_records(events=ALL_TYPES, n=300, seed=4), (300, 99_000, b"")]
    whole = build_usd(version=version, events=ALL_TYPES, records=records, crc=False)
    crc = struct.pack("<I", zlib.crc32(whole))
    if case.startswith("cut-"):
        more = build_usd(version=version, events=ALL_TYPES, records=[(7, 99_500, bytes(20))],
                         crc=False)[len(usd_header(version=version, events=ALL_TYPES)):]
        return records, whole + crc, whole + more[:int(case[4:])]
    return records, whole + crc, {"intact": whole + crc, "no-trailer": whole,
                                  "bad-crc": whole + bytes([crc[0] ^ 1]) + crc[1:]}[case]


@pytest.mark.parametrize("version", [1, 2])
@pytest.mark.parametrize("case", ["intact", "bad-crc", "no-trailer",
                                  *(f"cut-{k}" for k in _CUTS)])
def test_a_log_cut_before_its_crc_trailer_keeps_every_complete_record(tmp_path, version, case):
    """The deck writes its CRC only when logging stops; cut before that (power lost), the last
    4 bytes were taken as the CRC: the complete record they end dropped as cut short (or, cut
    1-3 bytes into the next record, the one before it). Every complete record is kept, and the
    log is said to be cut, not to have a CRC that does not match (``usddeck.c``)."""
    records, intact, data = _cut_log(version, case)
    path = tmp_path / "log"
    path.write_bytes(data)
    log = read_usd(path, allow_damaged=True)
    _assert_as_reference(intact, log)  # every record written, none more
    assert sum(len(e.timestamps_s) for e in log.events.values()) == len(records)
    assert log.crc_ok == (case == "intact") and log.has_crc == (case in ("intact", "bad-crc"))
    if case == "intact":
        assert log.problems == [] and read_usd(path).problems == []
        return
    where = "after a complete record" if case == "no-trailer" else "inside a record"
    cut = f"no CRC trailer: the file ends {where}, cut before the deck wrote its CRC"
    with pytest.raises(UsdFormatError, match="CRC mismatch" if case == "bad-crc" else
                       f"{cut} .*--allow-damaged"):
        read_usd(path)
    expected = {"bad-crc": ["CRC mismatch (stored "], "no-trailer": [cut]}.get(case, [
        cut, f"last record truncated at byte {len(intact) - 4}; dropped, the records before "
        "it kept"])
    assert [p[:len(e)] for p, e in zip(log.problems, expected, strict=True)] == expected
