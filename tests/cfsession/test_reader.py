"""cfsession.reader on its own: streams as arrays, rows never written, gaps, phases, events and
the one-line errors of a session that lacks what is asked. (Write-then-read of every stream:
test_writer.py; hostile files: test_untrusted.py; killed writers: test_crash.py.)"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from cfsession import Session, SessionError, SessionWriter, open_session, standard_streams
from cfsession.schema import log_block_spec

PERIOD = 0.02
FW_STEPS_MS = [20] * 10 + [40] + [20] * 10 + [80] + [20] * 10  # 1 then 3 packets lost
PHASES = [(0.0, "takeoff", "takeoff"), (0.1, "airborne-1", "airborne"), (0.2, "hover", "hover"),
          (0.3, "airborne-2", "airborne"), (0.5, "landing", "landing")]


def _write(path, *, compress: bool = True):
    gyro = log_block_spec(name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"],
                          period_s=PERIOD)
    with SessionWriter(path, streams=[gyro, *standard_streams()],
                       metadata={"uri": "sim://0", "params": {"kp": 2.5}, "note": "{oops"},
                       compress_on_close=compress) as w:
        for i, (t, name, kind) in enumerate(PHASES):
            w.phase(t=t, phase_id=i, name=name, kind=kind)
        fw = np.concatenate([[1000], 1000 + np.cumsum(FW_STEPS_MS)])
        for k, ms in enumerate(fw):
            w.append("gyro", (0.003 + 0.02 * k, int(ms), float(k), 2.0 * k, -1.0))
        w.append("setpoints", (0.6, 1.0, 2.0, 3.0, 30000, 4, 0))
        w.event(t=0.25, text="low battery", level="warning", source="runner")
    return path


@pytest.fixture(scope="module")
def session(tmp_path_factory) -> Session:
    return open_session(_write(tmp_path_factory.mktemp("reader") / "s.h5"))


def test_a_stream_is_its_value_columns_as_float64(session):
    gyro = session["gyro"]
    assert gyro.value_fields == ["x", "y", "z"] and len(gyro) == 33
    values = gyro.values()
    assert values.shape == (33, 3) and values.dtype == np.float64
    np.testing.assert_array_equal(gyro.values(["z", "x"])[:3], [[-1.0, 0.0], [-1.0, 1.0],
                                                                [-1.0, 2.0]])
    np.testing.assert_allclose(gyro.time[:2], [0.003, 0.023])
    with pytest.raises(SessionError, match=r"stream 'gyro' has no field\(s\) \['w'\]; has "
                                           r"\['x', 'y', 'z'\]"):
        gyro.values(["x", "w"])


def test_firmware_time_belongs_to_log_streams_only(session):
    assert session["setpoints"].fw_time_s is None and session["setpoints"].gaps() == []
    fw = session["gyro"].fw_time_s
    assert fw[0] == 1.0 and fw[-1] == pytest.approx(1.0 + sum(FW_STEPS_MS) / 1000)


def test_gaps_count_the_missing_packets_and_tolerance_decides_what_a_gap_is(session):
    gaps = session["gyro"].gaps()
    assert [(g.missing, round(g.end_s - g.start_s, 3)) for g in gaps] == [(1, 0.04), (3, 0.08)]
    assert [g.missing for g in session["gyro"].gaps(tolerance=2.5)] == [3]  # > 70 ms only
    assert session.dropped() == {"gyro": 4} and session.gaps() == gaps


def test_phase_windows_run_to_the_next_phase_and_kinds_span_first_to_last(session):
    phases = session.phases()
    assert [(p.name, p.start_s, p.end_s) for p in phases[:2]] == [("takeoff", 0.0, 0.1),
                                                                 ("airborne-1", 0.1, 0.2)]
    assert phases[-1].end_s == session.duration == pytest.approx(0.643)  # the last row, any stream
    assert session.phase_window("airborne") == (0.1, 0.5)  # airborne-1 to the end of -2
    assert session.phase_window("hover") == (0.2, 0.3)
    with pytest.raises(SessionError) as info:
        session.phase_window("excitation")
    msg = str(info.value)
    assert "no phase 'excitation'" in msg and "'airborne-2'" in msg and "'landing'" in msg
    assert "\n" not in msg and "did you mean" not in msg
    with pytest.raises(SessionError, match=r"no phase 'hovr' \(did you mean 'hover'\?\)"):
        session.phase_window("hovr")  # --window with a typo (first-day review)


def test_a_missing_stream_is_a_one_line_error_naming_the_streams(session):
    assert "gyro" in session and "acc" not in session
    with pytest.raises(SessionError) as info:
        session["acc"]
    assert "no stream 'acc'; streams are ['events', 'gyro', 'link', 'phases', 'setpoints']" in \
        str(info.value)


def test_json_metadata_decodes_or_falls_back(session):
    assert session.json_meta("params") == {"kp": 2.5}
    assert session.json_meta("note", default="n/a") == "n/a"  # not JSON
    assert session.json_meta("missing") is None and session.meta["uri"] == "sim://0"
    assert session.closed_cleanly and session.problems == [] and session.schema_version == 1


def test_events_keep_level_and_source(session):
    (event,) = session.events()
    assert (event.t, event.level, event.source, event.text) == (0.25, "warning", "runner",
                                                                "low battery")


def test_rows_allocated_but_never_written_are_dropped(tmp_path):
    """A writer killed between growing a dataset and filling it leaves rows of fill value (NaN
    host time); the reader drops them instead of handing NaN rows on."""
    path = _write(tmp_path / "s.h5", compress=False)
    with h5py.File(path, "a") as f:
        ds = f["gyro/data"]
        ds.resize((ds.shape[0] + 5,))
        assert np.isnan(ds[-1]["host_time"])
    s = open_session(path)
    assert len(s["gyro"]) == 33 and not np.isnan(s["gyro"].time).any()
