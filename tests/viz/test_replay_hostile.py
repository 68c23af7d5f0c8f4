"""``groundstation replay`` of session files made elsewhere, each damaged in one way the
session reader lets through (a review, 2026-11-27): a traceback or a hang before, a recording
and a warning now."""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main as gs_main

HOST = ("host_time", "<f8")
LOG = [HOST, ("fw_time_ms", "<u4"), ("x", "<f4")]
NOTES = [HOST, ("note", "S20")]  # an "events" or "phases" stream without their fields
LIVE = [HOST, ("order", "<f8"), ("pole_re_1", "<f8"), ("pole_im_1", "<f8")]


def _craft(path: Path, *, attrs: dict | None = None, extra: tuple | None = None) -> Path:
    """A minimal session (a 50-row log block) with root ``attrs`` and one ``extra`` stream
    ``(name, kind, dtype, rows)``, written with h5py as another tool would."""
    log = np.zeros(50, dtype=LOG)
    log["host_time"] = np.arange(50) * 0.02
    log["fw_time_ms"] = 1000 + 20 * np.arange(50)
    log["x"] = np.sin(np.arange(50) * 0.1)
    streams = [("gyro", "log", log)]
    if extra is not None:
        name, kind, dtype, rows = extra
        streams.append((name, kind, np.array(rows, dtype=dtype)))
    with h5py.File(path, "w") as f:
        f.attrs.update({"schema": "crazyflie-flight-session", "schema_version": 1,
                        "closed_cleanly": 1, **(attrs or {})})
        for name, kind, arr in streams:
            g = f.create_group(name)
            g.attrs["kind"] = kind
            ds = g.create_dataset("data", data=arr, maxshape=(None,), chunks=True)
            ds.attrs["units"] = ["s"] + [""] * (len(arr.dtype.names) - 1)
            ds.attrs["sources"] = [""] * len(arr.dtype.names)
    return path


CASES = {
    "summary a list": {"attrs": {"summary": "[1, 2]"}},
    "uri an array": {"attrs": {"uri": np.array([1.0, 2.0])}},
    "events without fields": {"extra": ("notes", "events", NOTES, [(0.1, b"x")])},
    "phases without fields": {"extra": ("marks", "phases", NOTES, [(0.1, b"x")])},
    "live id order 3e9": {"extra": ("live_id", "live_id", LIVE, [(0.5, 3e9, 0.9, 0.0)])},
    "live id order NaN": {"extra": ("live_id", "live_id", LIVE, [(0.5, np.nan, 0.9, 0.0)])},
    "live id time inf": {"extra": ("live_id", "live_id", LIVE, [(np.inf, 1, 0.9, 0.0),
                                                                (0.5, 1, 0.9, 0.0)])},
}


@pytest.mark.parametrize("case", CASES)
def test_a_damaged_session_replays_with_its_good_streams(case, tmp_path):
    session = _craft(tmp_path / "s.h5", **CASES[case])
    res = CliRunner().invoke(gs_main, ["replay", str(session), "--rrd", str(tmp_path / "o.rrd")])
    assert res.exit_code == 0 and res.exception is None, res.output
    assert (tmp_path / "o.rrd").stat().st_size > 0 and "gyro" not in res.stderr


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="POSIX FIFO")
def test_an_rrd_that_is_a_fifo_is_one_line_not_a_wait(tmp_path):
    """Rerun opened the FIFO and waited for a reader, Ctrl-C ignored."""
    fifo = tmp_path / "view.rrd"
    os.mkfifo(fifo)
    session = _craft(tmp_path / "s.h5")
    res = CliRunner().invoke(gs_main, ["replay", str(session), "--rrd", str(fifo)])
    assert res.exit_code == 2 and "is not a regular file (a FIFO" in res.output


def test_a_row_with_no_usable_time_is_left_out_not_its_stream(tmp_path, caplog):
    """One host_time of inf (or beyond Rerun's int64 nanoseconds) made the whole stream vanish
    from the recording, exit 0, with only Rerun's own warning (review)."""
    from tests.viz.rrd import load

    session = _craft(tmp_path / "s.h5")
    with h5py.File(session, "r+") as f:
        rows = f["gyro/data"][...]
        rows["host_time"][5], rows["host_time"][7] = np.inf, 1e300
        f["gyro/data"][...] = rows
    with caplog.at_level("WARNING", logger="groundstation.live"):
        res = CliRunner().invoke(gs_main, ["replay", str(session), "--rrd",
                                           str(tmp_path / "o.rrd")])
    assert res.exit_code == 0, res.output
    shown = [e for p, e in load(tmp_path / "o.rrd").items() if p.startswith("/gyro/")]
    assert shown and all(len(e.times["host_time"]) == 48 for e in shown)
    assert any("2 row(s) of gyro have no usable time" in r.getMessage() for r in caplog.records)


PHASES = [HOST, ("phase_id", "<i2"), ("name", "S32"), ("kind", "S16")]
EVENTS = [HOST, ("level", "u1"), ("source", "S16"), ("text", "S20"), ("cont", "u1")]


@pytest.mark.parametrize("case", ["phases", "events", "log"])
def test_a_phase_or_event_with_no_usable_time_is_left_out_not_the_others(tmp_path, caplog,
                                                                          case):
    """One phase at -inf s made Rerun drop every phase ("malformed chunk", a RerunWarning, exit
    0); an event likewise; a log block whose every time was 1e300 gave numpy's overflow warning
    (review D). The others are shown, the bad rows named in one warning."""
    import warnings

    from groundstation.live_layout import EVENTS as EVENTS_PATH
    from groundstation.live_layout import PHASE
    from tests.viz.rrd import load

    rows = {"phases": ("phases", "phases", PHASES, [(0.1, 0, b"a", b"hover"),
                                                     (-np.inf, 1, b"b", b"hover"),
                                                     (0.5, 2, b"c", b"landing")]),
            "events": ("events", "events", EVENTS, [(0.1, 2, b"runner", b"one", 0),
                                                     (np.inf, 2, b"runner", b"two", 0),
                                                     (0.5, 2, b"runner", b"three", 0)]),
            "log": ("acc", "log", LOG, [(1e300, 1000, 0.5), (2e300, 1020, 0.6)])}[case]
    session = _craft(tmp_path / "s.h5", extra=rows)
    with caplog.at_level("WARNING", logger="groundstation.live"), \
            warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        res = CliRunner().invoke(gs_main, ["replay", str(session), "--rrd",
                                           str(tmp_path / "o.rrd")])
    assert res.exit_code == 0, res.output
    assert not [w for w in caught if "Warning" in w.category.__name__], [
        str(w.message)[:200] for w in caught]
    n_bad = 2 if case == "log" else 1
    assert any(f"{n_bad} row(s) of {'acc' if case == 'log' else case} have no usable time"
               in r.getMessage() for r in caplog.records)
    if case != "log":
        entity = load(tmp_path / "o.rrd")[PHASE if case == "phases" else EVENTS_PATH]
        assert list(entity.times["host_time"]) == [0.1, 0.5]


def test_the_row_count_is_of_the_rows_replayed(tmp_path):
    """Rows with no usable time are left out of the recording, yet the count said 49 rows
    for 47 shown (review): it counts what was replayed and says how many were left out and
    why, in the one line. A row never written (NaN host_time) is no row of the session."""
    session = _craft(tmp_path / "s.h5", extra=("phases", "phases", PHASES, [
        (0.1, 0, b"a", b"hover"), (np.inf, 1, b"b", b"hover")]))
    with h5py.File(session, "r+") as f:
        rows = f["gyro/data"][...]
        rows["host_time"][5], rows["host_time"][7], rows["host_time"][9] = np.inf, 1e300, np.nan
        f["gyro/data"][...] = rows
    res = CliRunner().invoke(gs_main, ["replay", str(session), "--rrd", str(tmp_path / "o.rrd")])
    assert res.exit_code == 0, res.output
    assert f"wrote {tmp_path / 'o.rrd'} (48 rows from 2 streams; 3 rows with no usable time " \
           "left out)" in res.stdout


def test_events_left_out_count_with_the_rows_that_continue_them():
    """An event whose first row has no usable time is left out with its continuation rows,
    also when they come in the next block; an event continued from a shown one is shown."""
    import rerun as rr

    from cfsession.schema import Field, StreamSpec
    from groundstation.live import RerunView

    spec = StreamSpec(name="events", kind="events", fields=tuple(
        Field(n, t, "", "") for n, t in EVENTS))
    view = RerunView(rec=rr.RecordingStream("test-events"), background=False)
    view.begin(streams=[spec], metadata={})
    view.send_block("events", np.array([(0.1, 2, b"r", b"one", 0), (0.1, 2, b"r", b"+", 1),
                                        (np.inf, 2, b"r", b"two", 0)], dtype=EVENTS))
    view.send_block("events", np.array([(0.3, 2, b"r", b"+", 1), (0.4, 2, b"r", b"three", 0),
                                        (np.nan, 2, b"r", b"+", 1)], dtype=EVENTS))
    assert view.sent_rows == {"events": 4} and view.untimed_rows == {"events": 2}
