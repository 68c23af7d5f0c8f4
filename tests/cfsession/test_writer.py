"""Write-then-reread: the session format's main test, plus crashes and bad files."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from cfsession import SessionWriter, open_session, standard_streams
from cfsession.schema import TEXT_BYTES, log_block_spec
from groundstation.cli import main as cli
from groundstation.errors import SessionError

PERIOD = 0.02


def blocks():
    return [
        log_block_spec(
            name="motors",
            variables=[(f"motor.m{i}", "uint16_t") for i in range(1, 5)],
            period_s=PERIOD,
        ),
        log_block_spec(
            name="acc", variables=[(f"acc.{a}", "float") for a in "xyz"], period_s=PERIOD
        ),
        log_block_spec(
            name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"], period_s=PERIOD
        ),
    ]


def write_flight(path, *, n=600, drop=(), fw0=1000, compress=True, rng=None):
    """A 12 s synthetic flight; returns what was written, per stream, for comparison."""
    rng = rng or np.random.default_rng(0)
    sent = {k: [] for k in ("motors", "acc", "gyro", "setpoints", "link")}
    meta = {
        "uri": "radio://0/80/2M/E7E7E7E7E7",
        "plan_name": "unit",
        "plan_text": "[plan]\nx = 1\n",
        "params": {"pid_rate.roll_kp": 250.0},
        "protocol_version": 12,
    }
    with SessionWriter(
        path, streams=[*blocks(), *standard_streams()], metadata=meta, compress_on_close=compress
    ) as w:
        w.phase(t=0.0, phase_id=0, name="takeoff", kind="takeoff")
        for k in range(n):
            t = k * PERIOD + 0.003
            fw = (fw0 + 20 * k) % (1 << 24)
            if k == n // 2:
                w.phase(t=t, phase_id=1, name="excite", kind="excitation")
            if k in drop:
                continue
            rows = {
                "motors": (t, fw, *rng.integers(0, 65536, 4).tolist()),
                "acc": (t, fw, *rng.normal(size=3).astype(np.float32).tolist()),
                "gyro": (t, fw, *rng.normal(size=3).astype(np.float32).tolist()),
            }
            for name, row in rows.items():
                w.append(name, row)
                sent[name].append(row)
            if k % 5 == 0:
                sp = (t, 10.0, -5.0, 20.0, 36000, 1 if k >= n // 2 else 0, k // 5)
                w.append("setpoints", sp)
                sent["setpoints"].append(sp)
                w.append("link", (t, 98.0, 4.5))
                sent["link"].append((t, 98.0, 4.5))
        w.event(t=1.0, text="short", level="warning", source="link")
        # 2-byte characters after one ASCII byte: a row boundary splits a character
        w.event(t=2.0, text="x" + "é" * TEXT_BYTES, source="console")
    return sent


def test_round_trip_every_stream(tmp_path):
    path = tmp_path / "f.h5"
    sent = write_flight(path)
    s = open_session(path)
    assert s.closed_cleanly and s.problems == []
    for name, rows in sent.items():
        expected = np.array(rows, dtype=s[name].data.dtype)
        np.testing.assert_array_equal(s[name].data, expected)
    assert s["motors"].units["m1"] == "PWM (0-65535)"
    assert s["acc"].units["z"] == "g" and s["gyro"].units["x"] == "deg/s"
    assert s["gyro"].sources["y"] == "gyro.y" and s["gyro"].units["host_time"] == "s"
    assert s["setpoints"].units["yaw_rate"] == "deg/s"
    assert s["motors"].data.dtype["m1"] == np.uint16
    assert s.json_meta("params") == {"pid_rate.roll_kp": 250.0}
    assert s.meta["plan_text"] == "[plan]\nx = 1\n" and s.meta["protocol_version"] == 12
    assert s.meta["start_time_iso"].endswith("Z") and s.meta["start_time_ns"] > 1.6e18
    events = s.events()
    assert [(e.level, e.source, e.text) for e in events] == [
        ("warning", "link", "short"),
        ("info", "console", "x" + "é" * TEXT_BYTES),
    ]
    phases = s.phases()
    assert [(p.name, p.kind) for p in phases] == [("takeoff", "takeoff"), ("excite", "excitation")]
    assert phases[1].start_s == pytest.approx(300 * PERIOD + 0.003)
    assert phases[1].end_s == pytest.approx(s.duration)
    assert s.phase_window("excitation") == (phases[1].start_s, phases[1].end_s)
    assert s["gyro"].values().shape == (600, 3)
    assert s.dropped() == {"motors": 0, "acc": 0, "gyro": 0}


def test_gaps_found_across_timestamp_wrap(tmp_path):
    path = tmp_path / "gaps.h5"
    # 24-bit ms tick wraps during the flight; packets 100-102 and 400 are lost.
    write_flight(path, drop={100, 101, 102, 400}, fw0=(1 << 24) - 20 * 250, compress=False)
    s = open_session(path)
    gyro = s["gyro"]
    assert np.all(np.diff(gyro.fw_time_s) > 0), "wrap-around must be undone"
    gaps = gyro.gaps()
    assert [g.missing for g in gaps] == [3, 1]
    assert gaps[0].end_s - gaps[0].start_s == pytest.approx(4 * PERIOD)
    assert s.dropped() == {"motors": 4, "acc": 4, "gyro": 4}


def test_existing_file_is_never_overwritten(tmp_path):
    path = tmp_path / "f.h5"
    write_flight(path, n=20)
    before = path.read_bytes()
    with pytest.raises(SessionError, match="already exists"):
        SessionWriter(path, streams=standard_streams())
    assert path.read_bytes() == before


def _one_line_error(path):
    with pytest.raises(SessionError) as info:
        open_session(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg
    return msg


def test_bad_files_give_one_line_errors(tmp_path):
    assert "no such file" in _one_line_error(tmp_path / "missing.h5")
    assert "folder" in _one_line_error(tmp_path)
    text = tmp_path / "notes.txt"
    text.write_text("not hdf5\n" * 100)
    assert "not an HDF5 file" in _one_line_error(text)
    other = tmp_path / "other.h5"
    with h5py.File(other, "w") as f:
        f["x"] = np.arange(3)
    assert "not a flight session" in _one_line_error(other)
    newer = tmp_path / "newer.h5"
    write_flight(newer, n=10, compress=False)
    with h5py.File(newer, "r+") as f:
        f.attrs["schema_version"] = 99
    assert "upgrade" in _one_line_error(newer)
    cut = tmp_path / "cut.h5"
    write_flight(tmp_path / "full.h5", n=50)
    cut.write_bytes((tmp_path / "full.h5").read_bytes()[:3000])
    assert "damaged" in _one_line_error(cut)


def test_damaged_chunk_reads_as_far_as_it_goes(tmp_path):
    path = tmp_path / "f.h5"
    write_flight(path, n=600)  # compressed: a corrupted chunk fails to inflate
    with h5py.File(path, "r") as f:
        ds = f["gyro/data"]
        chunk_rows = ds.chunks[0]
        info = ds.id.get_chunk_info(3)
    raw = bytearray(path.read_bytes())
    raw[info.byte_offset : info.byte_offset + info.size] = b"\xff" * info.size
    path.write_bytes(bytes(raw))
    s = open_session(path)
    assert len(s["gyro"]) == 3 * chunk_rows
    assert any("gyro" in p and "unreadable" in p for p in s.problems)
    assert len(s["acc"]) == 600  # the other streams are intact


def test_info_command(tmp_path):
    path = tmp_path / "f.h5"
    write_flight(path, drop={7})
    runner = CliRunner()
    result = runner.invoke(cli, ["info", str(path), "--json"])
    assert result.exit_code == 0, result.output
    d = json.loads(result.output)
    assert d["streams"]["gyro"]["dropped"] == 1 and d["streams"]["gyro"]["expected"] == 600
    assert d["streams"]["setpoints"]["rate_hz"] == pytest.approx(10.0)
    assert [p["kind"] for p in d["phases"]] == ["takeoff", "excitation"]
    human = runner.invoke(cli, ["info", str(path)])
    assert human.exit_code == 0 and "gyro" in human.output and "excite" in human.output
    bad = runner.invoke(cli, ["info", str(tmp_path / "nope.h5")])
    assert bad.exit_code == 2
    assert bad.output.strip().count("\n") == 0 and "no such file" in bad.output


def test_a_slow_fsync_never_blocks_the_writer(tmp_path, monkeypatch):
    """fsync runs off the caller's thread (the flight runner's); close waits for it."""
    import threading

    import cfsession.writer as session_module

    release, calls = threading.Event(), []

    def slow_fsync(fd):
        calls.append(fd)
        release.wait(10)  # a card that takes "forever" to sync

    monkeypatch.setattr(session_module.os, "fsync", slow_fsync)
    w = SessionWriter(tmp_path / "f.h5", streams=blocks(), fsync_interval=0.0,
                      flush_interval=0.0, compress_on_close=False)
    for k in range(50):  # each append flushes; the first starts a background fsync
        w.append("gyro", (k * 0.02, 20 * k, 0.0, 0.0, 0.0))
    assert len(calls) == 1  # still blocked: no pile-up of sync threads, no blocked appends
    assert w.counts()["gyro"] == 50
    closer = threading.Thread(target=w.close)
    closer.start()
    closer.join(0.2)
    assert closer.is_alive(), "close must wait for the running fsync"
    release.set()
    closer.join(10)
    assert not closer.is_alive() and len(calls) == 2  # ... then syncs once more itself
    assert len(open_session(tmp_path / "f.h5")["gyro"]) == 50


def test_a_row_that_does_not_fit_costs_only_itself(tmp_path):
    """A malformed row (wrong length, text for a number) once made every flush raise: the rows
    buffered with it, and those after it, were lost and the file never closed cleanly."""
    path = tmp_path / "s.h5"
    w = SessionWriter(path, streams=[*blocks(), *standard_streams()], flush_interval=0.0)
    w.append("gyro", (0.00, 1000, 0.1, 0.2, 0.3))
    w.append("gyro", (0.02, 1020, 0.1))  # too short
    w.append("gyro", (0.04, 1040, "fast", 0.2, 0.3))  # no number
    w.event(t=0.05, text="after the bad rows")
    w.append("gyro", (0.06, 1060, 0.4, 0.5, 0.6))
    w.append("gyro", [0.07, 1070])  # a list: numpy spread it into every field, then raised
    w.append("gyro", 5.0)  # a scalar: spread into every field, silently
    w.flush()
    w.append("gyro", [0.08, 1080, 0.7, 0.8, 0.9])  # a whole row as a list is a row
    w.close(summary={"complete": True})
    assert any("4 row(s) of stream 'gyro'" in note for note in w.notes), w.notes
    s = open_session(path)
    assert s.closed_cleanly
    np.testing.assert_allclose(s["gyro"].values()[:, 0], [0.1, 0.4, 0.7], rtol=1e-6)
    events = s.events()
    assert [e.text for e in events] == [
        "after the bad rows", "4 row(s) of stream 'gyro' did not fit its fields and were left "
        "out"]
    assert events[1].level == "error" and events[1].source == "recorder"
