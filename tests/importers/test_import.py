"""Importers: cfclient CSV and uSD logs to session files, round trips with known values."""

from __future__ import annotations

import json
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main as gs
from groundstation.importers import CsvFormatError, read_cfclient_csv
from groundstation.session import open_session
from sysid.cli import main as sysid_cli
from sysid.session_io import load_session

CRAZYPAD = Path(__file__).resolve().parents[3] / "shared" / "data" / "crazypad"


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
    assert len(s["setpoints"]) == 0 and len(s["link"]) == 0
    [phase] = s.phases()
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
    """A format-2 uSD log: event 1 'fixedFrequency' (acc.x float, motor.m1 uint16) + CRC."""
    head = bytearray(b"\xbc" + struct.pack("<HH", 2, 2))
    head += struct.pack("<H", 1) + b"fixedFrequency\0" + struct.pack("<H", 2)
    head += b"acc.x(f)\0motor.m1(H)\0"
    head += struct.pack("<H", 7) + b"empty\0" + struct.pack("<H", 1) + b"mode(B)\0"
    for t, x, m in zip(stamps_us, a, b, strict=True):
        head += struct.pack("<HQfH", 1, int(t), float(x), int(m))
    return bytes(head) + struct.pack("<I", zlib.crc32(bytes(head)) & 0xFFFFFFFF)


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
    st = s["fixedFrequency"]
    assert "empty" not in s.streams  # event types without records are skipped
    np.testing.assert_array_equal(st.data["x"], acc)
    np.testing.assert_array_equal(st.data["m1"], m1)
    assert st.data.dtype["m1"] == np.uint16 and st.units["m1"] == "PWM (0-65535)"
    np.testing.assert_allclose(st.time, stamps / 1e6, rtol=0, atol=1e-12)  # µs kept
    np.testing.assert_array_equal(st.data["fw_time_ms"], np.round(stamps / 1000))
    assert "uSD" in s.meta["source_format"] and s.phases()[0].kind == "imported"
    again = CliRunner().invoke(gs, ["import", str(src), "--out", str(tmp_path / "o")])
    assert again.exit_code == 2 and "already exists" in again.stderr


def test_import_refuses_unknown_files(tmp_path) -> None:
    junk = tmp_path / "junk.bin"
    junk.write_bytes(b"\x00\x01hello")
    res = CliRunner().invoke(gs, ["import", str(junk), "--out", str(tmp_path)])
    assert res.exit_code == 2 and res.stderr.count("\n") == 1 and "junk.bin" in res.stderr


@pytest.mark.skipif(not CRAZYPAD.is_dir(), reason="shared CrazyPAD logs not present")
def test_crazypad_real_flight_imports_and_identifies(tmp_path) -> None:
    res = CliRunner().invoke(gs, ["import", str(CRAZYPAD / "controller_E8_log00"),
                                  str(CRAZYPAD / "motor_E8_log00"), "--out", str(tmp_path)])
    assert res.exit_code == 0, res.output
    s = open_session(tmp_path / "controller_E8_log00.h5")
    assert len(s["fixedFrequency"]) == 2606 and s.dropped() == {"fixedFrequency": 0}
    assert s["fixedFrequency"].units["r_roll"] == "rad/s"
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
