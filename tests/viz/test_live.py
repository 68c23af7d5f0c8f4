"""groundstation.live and replay: what reaches the .rrd equals the rows of the flight."""

from __future__ import annotations

import threading
from dataclasses import replace

import numpy as np
import pytest
import rerun as rr

from cfsession import SessionWriter, open_session
from cfsession.schema import log_block_spec
from groundstation.commands.replay import replay_session, specs_of
from groundstation.live import RerunView, ViewError, open_view
from tests.viz.rrd import blueprint_views, load
from tests.viz.sessions import (
    LONG_TEXT,
    N_LOG,
    flight_rows,
    flight_specs,
    live_id_rows,
    write_session,
)


def _live(path, *, batch: int = 3) -> RerunView:
    """Feed flight_rows() to a save-mode view from a runner thread, a few rows per call,
    streams interleaved as a flight delivers them."""
    view = open_view(mode="save", name="live", rrd_path=path)
    view.flush_interval = 0.01
    view.begin(streams=flight_specs(), metadata={"plan_name": "prbs-test", "uri": "sim://0"})
    rows = flight_rows()

    def runner():
        longest = max(len(r) for r in rows.values())
        for start in range(0, longest, batch):
            for name, rs in rows.items():
                if rs[start:start + batch]:
                    view.rows(name, rs[start:start + batch])

    th = threading.Thread(target=runner)
    th.start()
    th.join()
    view.end(summary={"packets_received": 1234})
    return view


def _check_flight(path):
    ents = load(path)
    rows = flight_rows()
    gyro = np.array(rows["gyro"])
    assert len(gyro) == N_LOG
    fw = np.array([r[1] for r in rows["gyro"]], dtype=np.int64)
    fw_s = (fw + (1 << 24) * np.cumsum(np.r_[0, np.diff(fw)] < 0)) / 1000.0
    for j, axis in enumerate("xyz"):
        e = ents[f"/gyro/{axis}"]
        assert len(e.scalars()) == N_LOG
        np.testing.assert_allclose(e.scalars(), gyro[:, 2 + j].astype(np.float32), rtol=1e-7)
        np.testing.assert_allclose(e.times["host_time"], gyro[:, 0], atol=1e-9)
        np.testing.assert_allclose(e.times["fw_time"], fw_s, atol=1e-9)  # wrap undone
        assert e.static["SeriesLines:names"] == [f"{axis} [deg/s]"]
    assert np.all(np.diff(ents["/gyro/x"].times["fw_time"]) > 0)
    for i in range(1, 5):
        np.testing.assert_array_equal(ents[f"/motors/m{i}"].scalars(),
                                      [r[1 + i] for r in rows["motors"]])
        assert ents[f"/motors/m{i}"].static["SeriesLines:names"] == [f"m{i} [PWM (0-65535)]"]
    assert ents["/acc/z"].static["SeriesLines:names"] == ["z [g]"]
    assert len(ents["/attitude/roll"].scalars()) == N_LOG // 2
    sp = np.array(rows["setpoints"])
    for j, axis in enumerate(("roll", "pitch", "yaw_rate", "thrust"), start=1):
        np.testing.assert_allclose(ents[f"/setpoints/{axis}"].scalars(), sp[:, j], rtol=1e-6)
    assert "/setpoints/phase_id" not in ents and "/setpoints/tick" not in ents
    link = np.array(rows["link"], dtype=float)
    for j, name in ((1, "quality"), (2, "latency_ms")):
        ok = np.isfinite(link[:, j])
        np.testing.assert_allclose(ents[f"/link/{name}"].scalars(), link[ok, j])
        np.testing.assert_allclose(ents[f"/link/{name}"].times["host_time"], link[ok, 0])
    events = ents["/events"]
    assert [t[0] for t in events.rows["TextLog:text"]] == [
        "[runner] armed", f"[safety] {LONG_TEXT}", "[link] link lost"]
    assert [lv[0] for lv in events.rows["TextLog:level"]] == ["INFO", "WARN", "ERROR"]
    np.testing.assert_allclose(events.times["host_time"], [0.5, 1.5, 4.9])
    phase = ents["/phase"]
    assert [s[0] for s in phase.rows["StateChange:state"]] == [
        "takeoff (takeoff)", "prbs (excitation)", "land (landing)"]
    np.testing.assert_allclose(phase.times["host_time"], [0.0, 2.0, 4.0])
    doc = ents["/session"].static["TextDocument:text"][0]
    assert "**plan_name**: prbs-test" in doc and "**uri**: sim://0" in doc
    return ents


def test_replay_shows_every_row(tmp_path):
    session = open_session(write_session(tmp_path / "flight.h5"))
    view = open_view(mode="save", name="replay", rrd_path=tmp_path / "replay.rrd")
    counts = replay_session(session=session, view=view)
    assert counts == {name: len(r) for name, r in flight_rows().items()}
    ents = _check_flight(tmp_path / "replay.rrd")
    assert '"duration_s": 4.99' in ents["/session"].static["TextDocument:text"][0]


@pytest.mark.parametrize("batch", [2, 7])  # 2: the continued event text comes in a later call
def test_live_listener_equals_replay(tmp_path, batch):
    view = _live(tmp_path / "live.rrd", batch=batch)
    assert view.dropped_rows == 0
    ents = _check_flight(tmp_path / "live.rrd")
    assert '"packets_received": 1234' in ents["/session"].static["TextDocument:text"][0]


def test_blueprint_puts_setpoints_next_to_what_they_command(tmp_path):
    view = open_view(mode="save", name="bp", rrd_path=tmp_path / "bp.rrd")
    view.begin(streams=flight_specs(), metadata={})
    view.end(summary={})
    views = blueprint_views(tmp_path / "bp.rrd")
    assert views["yaw rate [deg/s]"] == ["/setpoints/yaw_rate", "/gyro/z"]
    assert views["roll, pitch [deg]"] == [
        "/setpoints/roll", "/setpoints/pitch", "/attitude/roll", "/attitude/pitch"]
    for name in ("motors [PWM]", "acc [g]", "gyro [deg/s]", "link quality [%]",
                 "latency [ms]", "thrust [PWM]", "events", "phase", "session"):
        assert name in views
    # Without a stabilizer block, roll/pitch setpoints stand alone: no gyro rates beside them;
    # a block mixing units gets one panel per unit.
    mixed = log_block_spec(name="mixed", variables=[("baro.asl", "float"),
                                                    ("pm.vbat", "float")], period_s=0.1)
    specs = [s for s in flight_specs() if s.name != "attitude"] + [mixed]
    view = open_view(mode="save", name="bp2", rrd_path=tmp_path / "bp2.rrd")
    view.begin(streams=specs, metadata={})
    view.end(summary={})
    views = blueprint_views(tmp_path / "bp2.rrd")
    assert views["roll, pitch [deg]"] == ["/setpoints/roll", "/setpoints/pitch"]
    assert views["mixed [m]"] == ["/mixed/asl"] and views["mixed [V]"] == ["/mixed/vbat"]
    # setpoints and link streams named otherwise (a file made elsewhere): found by their kind
    new = {"setpoints": "commander", "link": "radio"}
    specs = [replace(s, name=new.get(s.name, s.name)) for s in flight_specs()]
    view = open_view(mode="save", name="bp3", rrd_path=tmp_path / "bp3.rrd")
    view.begin(streams=specs, metadata={})
    view.end(summary={})
    views = blueprint_views(tmp_path / "bp3.rrd")
    assert views["yaw rate [deg/s]"] == ["/commander/yaw_rate", "/gyro/z"]
    assert views["thrust [PWM]"] == ["/commander/thrust"]
    assert views["latency [ms]"] == ["/radio/latency_ms"]
    assert not [name for name in views if name.startswith(("commander.", "radio."))]


def test_replay_leaves_out_empty_streams(tmp_path):
    rows = flight_rows()
    with SessionWriter(tmp_path / "f.h5", streams=flight_specs()) as w:
        w.extend("gyro", rows["gyro"])
    view = open_view(mode="save", name="r", rrd_path=tmp_path / "r.rrd")
    assert replay_session(session=open_session(tmp_path / "f.h5"), view=view) == {"gyro": N_LOG}
    ents = load(tmp_path / "r.rrd")
    assert not any(e.startswith(("/link", "/setpoints", "/motors")) for e in ents)
    views = blueprint_views(tmp_path / "r.rrd")
    assert "gyro [deg/s]" in views and "link quality [%]" not in views


def _replay_counting_calls(tmp_path, monkeypatch, *, n: int) -> int:
    """Replay a flight with ``n`` live_id rows to ``tmp_path/live<n>.rrd``; the Rerun calls
    made."""
    calls = []
    for name in ("log", "send_columns", "set_time"):
        real = getattr(rr.RecordingStream, name)
        monkeypatch.setattr(rr.RecordingStream, name,
                            lambda *a, _real=real, **kw: calls.append(1) or _real(*a, **kw))
    session = open_session(write_session(tmp_path / f"live{n}.h5", live_id=n))
    view = open_view(mode="save", name="replay", rrd_path=tmp_path / f"live{n}.rrd")
    assert replay_session(session=session, view=view)["live_id"] == n
    monkeypatch.undo()
    return len(calls)


def test_replay_sends_every_live_id_update_in_blocks(tmp_path, monkeypatch):
    """Each update's poles, convergence values and status line, on host_time; as many Rerun
    calls for 300 updates as for 30 (a call per row: 100 000 rows took 25 s)."""
    few = _replay_counting_calls(tmp_path, monkeypatch, n=30)
    assert _replay_counting_calls(tmp_path, monkeypatch, n=300) == few
    data, ents = live_id_rows(300), load(tmp_path / "live300.rrd")
    t = data["host_time"]
    poles = ents["/live_id/z_plane/poles"]
    np.testing.assert_allclose(poles.times["host_time"], t, atol=1e-9)
    want = [[[data[f"pole_re_{i}"][k], data[f"pole_im_{i}"][k]]
             for i in range(1, min(int(o), 4) + 1)] for k, o in enumerate(data["order"])]
    assert [len(p) for p in poles.rows["Points2D:positions"]] == [len(w) for w in want]
    assert want[2] == [] and len(want[4]) == 4  # order 0; order 7 of 4 stored poles
    np.testing.assert_allclose(np.concatenate([p for p in poles.rows["Points2D:positions"] if p]),
                               np.concatenate([w for w in want if w]), rtol=1e-7)
    assert poles.rows["Points2D:radii"] == [[pytest.approx(0.015)]] * len(t)
    assert len(poles.rows["Points2D:colors"]) == len(t)
    for name in ("pole_move", "innovation_nvar", "fit_pct", "max_pole"):  # NaN: left out
        v = data[name].astype(float)
        ok = np.isfinite(v)
        series = ents[f"/live_id/convergence/{name}"]
        np.testing.assert_array_equal(series.scalars(), v[ok])
        np.testing.assert_allclose(series.times["host_time"], t[ok], atol=1e-9)
    status = ents["/live_id/status"]
    np.testing.assert_allclose(status.times["host_time"], t, atol=1e-9)
    texts = [line[0] for line in status.rows["TextLog:text"]]
    assert len(texts) == len(t) and texts[0] == (
        "update (recorded): order 4, innov. var [1] 0.5, 1-step fit [%] 50, max |pole| [1] 0.99")
    assert texts[6].startswith("update (recorded): order 4, pole move [1] 0.01429, innov.")
    assert "1-step fit" not in texts[6]  # NaN: left out
    assert len(ents["/live_id/convergence/fit_pct"].scalars()) == 300 - 300 // 7


def test_rows_never_raise_and_drop_when_far_behind(tmp_path, caplog):
    view = open_view(mode="save", name="drop", rrd_path=tmp_path / "drop.rrd")
    view.background = False  # nothing drains: the queue fills up
    view.max_pending_rows = 100
    view.begin(streams=flight_specs(), metadata={})
    gyro = flight_rows()["gyro"]
    for i in range(0, 150, 10):
        view.rows("gyro", gyro[i:i + 10])
    assert view.dropped_rows == 50
    view.flush()  # what the worker would do: the queue has room again
    view.rows("nonexistent", [(0.0, 1.0)])  # undeclared stream: warned, ignored
    view.rows("acc", [(0.0, 1)])  # malformed row: logged, the rest still shown
    view.end(summary={})
    ents = load(tmp_path / "drop.rrd")
    np.testing.assert_allclose(ents["/gyro/z"].scalars(), [r[4] for r in gyro[:100]], rtol=1e-6)
    assert not ents["/acc/x"].rows
    assert "dropping rows" in caplog.text and "'nonexistent'" in caplog.text
    assert "could not show 1 rows of acc" in caplog.text


def test_specs_of_session_round_trip(tmp_path):
    session = open_session(write_session(tmp_path / "flight.h5"))
    by_name = {s.name: s for s in specs_of(session)}
    for spec in flight_specs():
        got = by_name[spec.name]
        assert got.kind == spec.kind and got.dtype == spec.dtype
        assert [f.unit for f in got.fields] == [f.unit for f in spec.fields]
        assert [f.source for f in got.fields] == [f.source for f in spec.fields]


def test_open_view_errors(tmp_path):
    with pytest.raises(ViewError, match="view mode 'tv' is unknown; use one of rerun, serve"):
        open_view(mode="tv", name="x")
    with pytest.raises(ViewError, match="needs rrd_path"):
        open_view(mode="save", name="x")
