"""``groundstation info`` on imported logs: their time is the firmware's (it does not start at
0), and their period is estimated from the data, so the rows expected must match the rows there
are when nothing was dropped."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main as gs
from tests.paths import CRAZYPAD, needs_crazypad

LOG = "Gyro-20240101T10-00-00.csv"  # a cfclient block: the stream is named Gyro


def _ms_log(path: Path, *, start_ms: float, period_ms: float, n: int,
            drop: range = range(0)) -> Path:
    """A cfclient CSV whose logger ticks every ``period_ms`` on the firmware's millisecond
    clock (9 and 10 ms steps for 9.886 ms), rows ``drop`` lost."""
    ticks = np.round(start_ms + period_ms * np.arange(n)).astype(int)
    keep = np.setdiff1d(np.arange(n), np.array(list(drop), dtype=int))
    path.write_text("Timestamp,gyro.x\n" + "".join(f"{ticks[k]},{k % 7}\n" for k in keep))
    return path


def _info(tmp_path: Path, log: Path) -> tuple[dict, str]:
    res = CliRunner().invoke(gs, ["import", str(log), "--out", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    [session] = (tmp_path / "out").iterdir()
    as_json = CliRunner().invoke(gs, ["info", str(session), "--json"])
    text = CliRunner().invoke(gs, ["info", str(session), "--width", "120"])
    assert as_json.exit_code == 0 and text.exit_code == 0, as_json.output + text.output
    return json.loads(as_json.output), text.output


@pytest.mark.parametrize("period_ms", [9.886, 10.0, 4.0, 2.5])
def test_rows_expected_are_the_rows_logged_when_none_was_dropped(tmp_path, period_ms):
    d, _ = _info(tmp_path, _ms_log(tmp_path / LOG, start_ms=9696, period_ms=period_ms,
                                   n=2606))
    gyro = d["streams"]["Gyro"]
    assert (gyro["rows"], gyro["expected"], gyro["dropped"]) == (2606, 2606, 0)


def test_rows_expected_count_the_dropped_ones(tmp_path):
    d, _ = _info(tmp_path, _ms_log(tmp_path / LOG, start_ms=9696, period_ms=9.886,
                                   n=2606, drop=range(1000, 1005)))
    gyro = d["streams"]["Gyro"]
    assert (gyro["rows"], gyro["expected"], gyro["dropped"]) == (2601, 2606, 5)


def test_the_duration_of_an_imported_log_is_the_span_of_its_data(tmp_path):
    d, text = _info(tmp_path, _ms_log(tmp_path / LOG, start_ms=9696, period_ms=10.0,
                                      n=2576))
    assert d["time_s"] == pytest.approx([9.696, 35.446])
    assert d["duration_s"] == pytest.approx(25.75)
    assert "data 9.70 to 35.45 s of firmware time (25.75 s)" in text
    assert "duration 35.45" not in text
    assert open_session(d["path"]).meta["duration_s"] == pytest.approx(25.75)
    # the import's own summary (rows, airborne spans) is not a flight's: no "0 of 0 planned"
    assert d["summary"]["imported"] is True
    assert "flight summary" not in text and "planned sent" not in text


@needs_crazypad
def test_the_crazypad_log_expects_the_rows_it_has(tmp_path):
    d, text = _info(tmp_path, CRAZYPAD / "controller_E8_log00")
    e = d["streams"]["stateEstimate+controller"]
    assert (e["rows"], e["expected"], e["dropped"]) == (2606, 2606, 0)
    assert d["duration_s"] == pytest.approx(35.449 - 9.696, abs=1e-3)
    assert "data 9.70 to 35.45 s" in text
