"""Importers: cfclient CSV and uSD logs to session files, round trips with known values."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main as gs
from groundstation.importers import CsvFormatError, read_cfclient_csv
from sysid.cli import main as sysid_cli
from sysid.session_io import load_session
from tests.importers.usd_logs import build_usd
from tests.paths import CRAZYPAD, needs_crazypad


def write_csv(path: Path, header: list[str], rows: list[list]) -> Path:
    path.write_text("\n".join([",".join(header)] + [",".join(str(v) for v in r) for r in rows])
                    + "\n")
    return path


def cfclient_folder(tmp_path: Path) -> tuple[Path, np.ndarray, np.ndarray, np.ndarray]:
    """Two blocks of one cfclient session; the 24-bit tick wraps in the middle."""
    folder = tmp_path / "20240101T10-00-00"
    folder.mkdir()
    n = 50
    ms = ((1 << 24) - 250 + 10 * np.arange(n)) % (1 << 24)
    motors = np.arange(n)[:, None] * 100 + np.array([1, 2, 3, 4]) * 10000
    gyro = np.round(np.sin(np.arange(n)[:, None] * 0.1 + np.arange(3)), 6)
    motor_vars = [f"motor.m{i}" for i in range(1, 5)]
    write_csv(folder / "Motors-20240101T10-00-00.csv", ["Timestamp", *motor_vars],
              [[t, *m] for t, m in zip(ms, motors, strict=True)])
    write_csv(folder / "Gyro-20240101T10-00-02.csv", ["Timestamp", "gyro.x", "gyro.y", "gyro.z"],
              [[t + 3, *g] for t, g in zip(ms, gyro, strict=True)])
    return folder, ms, motors, gyro


def test_csv_folder_round_trip(tmp_path) -> None:
    folder, ms, motors, gyro = cfclient_folder(tmp_path)
    res = CliRunner().invoke(gs, ["import", str(folder), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    s = open_session(tmp_path / "out" / f"{folder.name}.h5")
    assert s.closed_cleanly and not s.problems
    unwrapped = ((1 << 24) - 250 + 10 * np.arange(len(ms))) / 1000.0
    np.testing.assert_array_equal(s["Motors"].values(), motors)
    np.testing.assert_allclose(s["Motors"].fw_time_s, unwrapped)
    np.testing.assert_allclose(s["Gyro"].values(), gyro)
    np.testing.assert_allclose(s["Gyro"].time, unwrapped + 0.003)
    assert s["Motors"].units["m1"] == "PWM (0-65535)" and s["Gyro"].units["z"] == "deg/s"
    assert s["Gyro"].sources["y"] == "gyro.y" and s["Motors"].period_s == 0.01
    assert set(s.streams) == {"Motors", "Gyro", "events", "phases"}  # no empty setpoints, link
    [phase] = s.phases()  # 0.49 s of motors on: too short for an airborne segment
    assert (phase.name, phase.start_s) == ("log", unwrapped[0])
    assert phase.end_s == pytest.approx(unwrapped[-1] + 0.003)
    assert s.meta["source_format"] == "cfclient log-to-file CSV"
    assert len(json.loads(s.meta["source_files"])) == 2
    d = load_session(s.path, inputs=["motor.m1", "motor.m2"], outputs=["gyro"], window="log",
                     dt=0.01, detrend=None)
    assert d.input_names == ("motor.m1", "motor.m2") and d.n_samples == len(ms) - 1
    # grid: from the gyro's first sample (3 ms after the motors') to the motors' last one
    np.testing.assert_array_equal(d.u[:, 0], motors[:-1, 0])
    np.testing.assert_allclose(d.y, gyro[:-1])


def test_csv_damage(tmp_path) -> None:
    ok = write_csv(tmp_path / "a.csv", ["Timestamp", "pm.vbat"], [[10, 3.7], [20, 3.6]])
    with open(ok, "a") as fh:
        fh.write("30,")  # killed while writing the last line
    log = read_cfclient_csv(ok)
    assert log.timestamps_s.tolist() == [0.01, 0.02] and log.ctypes["pm.vbat"] == "double"
    bad = write_csv(tmp_path / "b.csv", ["Timestamp", "x.y"], [[10, 1], [20, "nan?"], [30, 2]])
    with pytest.raises(CsvFormatError, match=r"b\.csv: line 3 has the non-number 'nan\?'"):
        read_cfclient_csv(bad)
    other = write_csv(tmp_path / "c.csv", ["time", "x"], [[1, 2]])
    with pytest.raises(CsvFormatError, match="not a cfclient log CSV"):
        read_cfclient_csv(other)


def usd_bytes(*, stamps_us: np.ndarray, a: np.ndarray, b: np.ndarray) -> bytes:
    """A format-2 uSD log: event 1 'fixedFrequency' (acc.x float, motor.m1 uint16), event 7
    'empty' declared without records, and the CRC."""
    return build_usd(version=2, events=[(1, "fixedFrequency", [("acc.x", "f"), ("motor.m1", "H")]),
                                        (7, "empty", [("mode", "B")])],
                     records=[(1, int(t), (float(x), int(m)))
                              for t, x, m in zip(stamps_us, a, b, strict=True)])


def test_usd_round_trip(tmp_path) -> None:
    n = 40
    stamps = 5_000_000 + 10_000 * np.arange(n) + np.arange(n) % 3 * 7  # µs, with jitter
    acc = np.float32(np.linspace(-1, 1, n))
    m1 = np.arange(n, dtype=np.uint16) * 1000
    src = tmp_path / "log07"
    src.write_bytes(usd_bytes(stamps_us=stamps, a=acc, b=m1))
    res = CliRunner().invoke(gs, ["import", str(src), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    s = open_session(tmp_path / "o" / "log07.h5")
    assert set(s.streams) == {"acc+motor", "events", "phases"}  # named after what it holds
    st = s["acc+motor"]
    assert st.attrs["source_event"] == "fixedFrequency"
    np.testing.assert_array_equal(st.data["x"], acc)
    np.testing.assert_array_equal(st.data["m1"], m1)
    assert st.data.dtype["m1"] == np.uint16 and st.units["m1"] == "PWM (0-65535)"
    np.testing.assert_allclose(st.time, stamps / 1e6, rtol=0, atol=1e-12)  # µs kept
    np.testing.assert_array_equal(st.data["fw_time_ms"], np.round(stamps / 1000))
    assert "uSD" in s.meta["source_format"] and s.phases()[0].kind == "imported"
    # no invented start time; the import said in words, not as a Python list
    assert s.meta["start_time_ns"] == 0 and s.meta["start_time_iso"].startswith("unknown")
    first = s.events()[0].text
    assert first == ("imported from crazyflie uSD-card deck log, format 2 (CRC ok): "
                     f"{src.resolve()}")
    assert "no airborne segments" in s.events()[1].text
    info = CliRunner().invoke(gs, ["info", str(s.path)])
    assert "start unknown (the log carries no wall-clock time)" in info.stdout
    again = CliRunner().invoke(gs, ["import", str(src), "--out", str(tmp_path / "o")])
    assert again.exit_code == 2 and "already exists; pass --force" in again.stderr


def test_import_refuses_unknown_files(tmp_path) -> None:
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01hello")
    res = CliRunner().invoke(gs, ["import", str(junk), "--out", str(tmp_path)])
    assert res.exit_code == 2 and res.stderr.count("\n") == 1 and "junk.bin" in res.stderr


@needs_crazypad
def test_crazypad_real_flight_imports_and_identifies(tmp_path) -> None:
    res = CliRunner().invoke(gs, ["import", str(CRAZYPAD / "controller_E8_log00"),
                                  str(CRAZYPAD / "motor_E8_log00"), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    s = open_session(tmp_path / "controller_E8_log00.h5")
    name = "stateEstimate+controller"
    assert len(s[name]) == 2606 and s.dropped() == {name: 0}
    assert s[name].units["r_roll"] == "rad/s"
    assert [p.name for p in s.phases()] == ["ground-0", "airborne-1", "ground-1", "airborne-2",
                                            "ground-2"]
    axes = ("roll", "pitch", "yaw")
    res = CliRunner().invoke(sysid_cli, [
        "identify", str(s.path), "--window", "all", "--dt", "0.01", "--order", "4",
        "--past", "20", "--future", "10", "--json",
        "--inputs", ",".join(f"controller.cmd_{a}" for a in (*axes, "thrust")),
        "--outputs", ",".join(f"controller.r_{a}" for a in axes)])
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert len(report["poles"]) == 4 and report["n_samples"][0] > 2500
    assert all(np.isfinite(v) for v in report["fit_percent"]["1-step"].values())


def test_a_folder_of_usd_logs_and_csv_folders(tmp_path):
    """A uSD card's files, a cfclient session folder beside them, and files that are neither."""
    card = tmp_path / "card"
    card.mkdir()
    n = 20
    for name in ("log00", "log01"):
        (card / name).write_bytes(usd_bytes(stamps_us=10_000 * np.arange(n),
                                            a=np.zeros(n, np.float32), b=np.zeros(n, np.uint16)))
    (card / "config.txt").write_text("1 # version\n")
    (card / ".hidden").mkdir()
    folder, *_ = cfclient_folder(card)
    res = CliRunner().invoke(gs, ["import", str(card), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "o").iterdir()) == [
        f"{folder.name}.h5", "log00.h5", "log01.h5"]
    assert "skipped 1 file(s) that are neither uSD logs nor cfclient CSVs: config.txt" in res.stderr
    assert open_session(tmp_path / "o" / f"{folder.name}.h5").streams.keys() >= {"Motors", "Gyro"}
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("hello")
    res = CliRunner().invoke(gs, ["import", str(empty), "--out", str(tmp_path / "o2")])
    assert res.exit_code == 2 and "holds no uSD-card deck logs" in res.stderr
    assert not (tmp_path / "o2").exists()


def test_two_sources_with_one_name_are_refused_before_any_work(tmp_path):
    n = 5
    for d in ("a", "b"):
        (tmp_path / d).mkdir()
        (tmp_path / d / "log00").write_bytes(usd_bytes(
            stamps_us=1000 * np.arange(n), a=np.zeros(n, np.float32), b=np.zeros(n, np.uint16)))
    res = CliRunner().invoke(gs, ["import", str(tmp_path / "a"), str(tmp_path / "b"),
                                  "--out", str(tmp_path / "o")])
    assert res.exit_code == 2 and "would both become log00.h5" in res.stderr
    assert not (tmp_path / "o").exists()


def test_existing_sessions_are_each_one_line_and_the_missing_ones_are_imported(tmp_path):
    """A card imported before, one session since deleted: it is imported again; each existing
    one is refused on its own line (never written over without --force); exit 2."""
    card = tmp_path / "card"
    card.mkdir()
    n = 20
    for i, name in enumerate(("log00", "log01", "log02")):
        (card / name).write_bytes(usd_bytes(stamps_us=10_000 * np.arange(n),
                                            a=np.full(n, i, np.float32), b=np.zeros(n, np.uint16)))
    out = tmp_path / "o"
    first = CliRunner().invoke(gs, ["import", str(card), "--out", str(out)])
    assert first.exit_code == 0, first.output
    (out / "log01.h5").unlink()
    kept = {p: p.read_bytes() for p in (out / "log00.h5", out / "log02.h5")}
    again = CliRunner().invoke(gs, ["import", str(card), "--out", str(out)])
    assert again.exit_code == 2 and "Traceback" not in again.output
    assert again.stderr.splitlines() == [
        f"error: {out / 'log00.h5'}: already exists; pass --force to replace it",
        f"error: {out / 'log02.h5'}: already exists; pass --force to replace it"]
    assert again.stdout.startswith(f"{out / 'log01.h5'}: acc+motor {n} rows")
    assert open_session(out / "log01.h5")["acc+motor"].data["x"].tolist() == [1.0] * n
    assert all(p.read_bytes() == b for p, b in kept.items())  # untouched
    forced = CliRunner().invoke(gs, ["import", str(card), "--out", str(out), "--force"])
    assert forced.exit_code == 0, forced.output
    assert sorted(p.name for p in out.iterdir()) == ["log00.h5", "log01.h5", "log02.h5"]


def test_repeated_time_stamps_are_flagged_and_not_a_1_ms_period(tmp_path) -> None:
    """Every Timestamp twice: the period read as 1 ms (the median step was 0), info showed 8991
    of 9991 rows "dropped" and sysid gridded at 1 ms (degenerate-data review). Now the period
    is the 10 ms of the positive steps, nothing dropped, and the repeats are a problem of the
    session, named with their first line."""
    stamps = np.repeat(1000 + 10 * np.arange(100), 2)
    path = write_csv(tmp_path / "Data-20240101T10-00-00.csv", ["Timestamp", "ext.u1"],
                     [[t, i % 7] for i, t in enumerate(stamps)])
    res = CliRunner().invoke(gs, ["import", str(path), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    [session] = (tmp_path / "out").glob("*.h5")
    s = open_session(session)
    assert s["Data"].period_s == 0.01 and s.dropped() == {"Data": 0}
    assert any("100 row(s) repeat the Timestamp of the row before (first: line 3, 1000 ms)" in p
               for p in s.problems), s.problems
