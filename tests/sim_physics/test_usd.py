"""The uSD-card log reader: real files, synthetic files with known content, damage."""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from groundstation.importers import UsdFormatError, read_usd
from tests.importers.usd_logs import build_usd
from tests.paths import CRAZYPAD, needs_crazypad


def _write(path, *, version: int, records: list[tuple[int, int, tuple]], crc_fix: int = 0):
    """A uSD log with event 7 'fixedFrequency' (a: float, b: uint16, c: int8) and event 9 'ev';
    ``crc_fix`` added to its CRC (a damaged log)."""
    body = build_usd(version=version, records=records, crc=False,
                     events=[(7, "fixedFrequency", [("g.a", "f"), ("g.b", "H"), ("g.c", "b")]),
                             (9, "ev", [("x", "e")])])
    path.write_bytes(body + struct.pack("<I", (zlib.crc32(body) + crc_fix) & 0xFFFFFFFF))
    return path


@pytest.mark.parametrize(("version", "unit"), [(1, 1e-3), (2, 1e-6)])
def test_synthetic_log_decodes_to_known_values(tmp_path, version, unit):
    recs = [(7, 1000, (1.5, 65535, -3)), (9, 1500, (0.25,)), (7, 2000, (-2.0, 7, 100))]
    log = _write(tmp_path / "log", version=version, records=recs)
    out = read_usd(log)
    assert out.version == version and out.crc_ok
    ff = out.events["fixedFrequency"]
    assert np.allclose(ff.timestamps_s, np.array([1000, 2000]) * unit)
    assert ff.values["g.a"].tolist() == [1.5, -2.0] and ff.values["g.b"].dtype == np.uint16
    assert ff.values["g.b"].tolist() == [65535, 7] and ff.values["g.c"].tolist() == [-3, 100]
    assert ff.as_array().shape == (2, 3)
    assert out.events["ev"].values["x"].tolist() == [0.25]


def test_crc_mismatch_is_reported_and_can_be_overridden(tmp_path):
    log = _write(tmp_path / "log", version=2, records=[(7, 5, (1.0, 1, 1))], crc_fix=1)
    with pytest.raises(UsdFormatError, match=r"CRC mismatch.*allow_damaged"):
        read_usd(log)
    out = read_usd(log, allow_damaged=True)
    assert not out.crc_ok and out.events["fixedFrequency"].values["g.a"].tolist() == [1.0]


def test_truncated_and_foreign_files(tmp_path):
    good = _write(tmp_path / "log", version=2, records=[(7, 5, (1.0, 1, 1))] * 3).read_bytes()
    body = good[:-4][:-3]                    # cut into the last record, valid CRC of the rest
    cut = tmp_path / "cut"
    cut.write_bytes(body + struct.pack("<I", zlib.crc32(body)))
    with pytest.raises(UsdFormatError, match="truncated"):
        read_usd(cut)
    assert len(read_usd(cut, allow_damaged=True).events["fixedFrequency"].timestamps_s) == 2
    other = tmp_path / "x.csv"
    other.write_text("Timestamp,acc.x\n")
    with pytest.raises(UsdFormatError, match="not a uSD"):
        read_usd(other)
    with pytest.raises(UsdFormatError, match="cannot read"):
        read_usd(tmp_path / "missing")


@needs_crazypad
def test_real_crazypad_logs():
    ev = read_usd(f"{CRAZYPAD}/motor_E8_log00").events["fixedFrequency"]
    t = ev.timestamps_s
    assert len(t) > 2500 and np.allclose(np.median(np.diff(t)), 0.01, rtol=0.02)   # 100 Hz
    assert list(ev.values)[:4] == ["motor.m1", "motor.m2", "motor.m3", "motor.m4"]
    vbat = ev.values["pm.vbatMV"]
    assert vbat.min() > 3300 and vbat.max() < 4300
