"""``groundstation export`` of an imported log: its ``host_time`` is the firmware's clock (the
log has no host), so every format names that column ``fw_time``; a flown session's keep
``host_time`` (tests/export/test_export.py)."""

from __future__ import annotations

import csv

import numpy as np
import pytest
import scipy.io
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main
from groundstation.importers import usd_to_session
from tests.importers.usd_logs import build_usd

EVENTS = [(1, "fixedFrequency", [("motor.m1", "H"), ("acc.z", "f")])]


@pytest.fixture(scope="module")
def imported(tmp_path_factory):
    d = tmp_path_factory.mktemp("export-imported")
    data = build_usd(version=2, events=EVENTS, records=[(1, 10_000 * k, (k, 0.5 * k))
                                                        for k in range(20)])
    (d / "log02").write_bytes(data)
    return usd_to_session(source=d / "log02", out=d / "log02.h5")


def _export(session, to, out):
    res = CliRunner().invoke(main, ["export", str(session), "--to", to, "--out", str(out)])
    assert res.exit_code == 0, res.output


def test_csv_labels_an_imported_logs_time_as_the_firmware_clock(imported, tmp_path):
    _export(imported, "csv", tmp_path / "csv")
    s = open_session(imported)
    for name in s.streams:  # the log stream, events and phases: all on the firmware clock
        with (tmp_path / "csv" / f"{name}.csv").open(newline="") as fh:
            rows = list(csv.reader(fh))
        assert rows[0][0] == "fw_time [s]", name
        assert "host_time [s]" not in rows[0]
    with (tmp_path / "csv" / "motor+acc.csv").open(newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:2] == ["fw_time [s]", "fw_time_ms [ms]"]
    np.testing.assert_array_equal([float(r[0]) for r in rows[1:]], s["motor+acc"].time)


def test_parquet_and_mat_name_it_alike(imported, tmp_path):
    pq = pytest.importorskip("pyarrow.parquet")
    _export(imported, "parquet", tmp_path / "pq")
    schema = pq.read_schema(tmp_path / "pq" / "motor+acc.parquet")
    assert schema.names[:2] == ["fw_time", "fw_time_ms"]
    assert schema.field("fw_time").metadata[b"unit"] == b"s"
    _export(imported, "mat", tmp_path / "log.mat")
    m = scipy.io.loadmat(tmp_path / "log.mat", simplify_cells=True)
    assert "host_time" not in m["streams"]["motor_acc"]
    np.testing.assert_array_equal(m["streams"]["motor_acc"]["fw_time"],
                                  open_session(imported)["motor+acc"].time)
    assert m["units"]["motor_acc"]["fw_time"] == "s"
    assert m["names"]["motor_acc"]["fields"]["fw_time"] == "host_time"  # the session's name
