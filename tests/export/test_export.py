"""``groundstation export``: CSV, MATLAB and Parquet read back equal the session."""

from __future__ import annotations

import csv
import json
import sys

import numpy as np
import pytest
import scipy.io
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main
from sysid.session_io import load_experiments, load_session
from tests.sysid.flights import known_system, write_flight
from tests.viz.sessions import LONG_TEXT, write_session


def _run(*args):
    return CliRunner().invoke(main, ["export", *map(str, args)])


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return write_session(tmp_path_factory.mktemp("export") / "flight.h5")


def test_csv_round_trip_with_units(session, tmp_path):
    out = tmp_path / "csv"
    res = _run(session, "--to", "csv", "--out", out)
    assert res.exit_code == 0, res.output
    s = open_session(session)
    for name, stream in s.streams.items():
        with (out / f"{name}.csv").open(encoding="utf-8") as fh:
            rows = list(csv.reader(fh))
        header, body = rows[0], rows[1:]
        if name == "events":
            assert header == ["host_time [s]", "level", "source", "text"]
            assert [r[3] for r in body] == [e.text for e in s.events()]
            assert LONG_TEXT in [r[3] for r in body]  # the continued text joined, intact
            continue
        data = stream.data
        for j, f in enumerate(data.dtype.names):
            unit = stream.units.get(f, "")
            assert header[j] == (f"{f} [{unit}]" if unit else f)
            col = [r[j] for r in body]
            if data[f].dtype.kind == "S":
                assert col == [v.decode() for v in data[f]]
            else:  # full precision: the stored values exactly
                np.testing.assert_array_equal(np.array(col, dtype=float),
                                              data[f].astype(float))
    assert "m1 [PWM (0-65535)]" in (out / "motors.csv").read_text().splitlines()[0]
    assert json.loads((out / "metadata.json").read_text())["schema_version"] == \
        s.schema_version
    # an existing, non-empty output needs --force; the session is never touched
    res = _run(session, "--to", "csv", "--out", out)
    assert res.exit_code == 2 and "--force" in res.output
    assert _run(session, "--to", "csv", "--out", out, "--force").exit_code == 0


def test_mat_holds_what_iddata_needs(tmp_path):
    flight = write_flight(tmp_path / "f.h5", system=known_system(), seed=4, n=800)
    out = tmp_path / "f.mat"
    res = _run(flight.path, "--to", "mat", "--out", out)
    assert res.exit_code == 0, res.output
    m = scipy.io.loadmat(out, simplify_cells=True)
    # what `sysid identify` identifies from (its channels and logged period, the excitation
    # phase), not detrended; the export had its own defaults (acc,gyro at 0.02 s: a 100 Hz
    # import was decimated; first-day audit)
    ref = load_session(flight.path, inputs=["motors"], outputs=["acc.z", "gyro"], dt=None,
                       detrend=None)
    np.testing.assert_allclose(m["u"], ref.u, rtol=0, atol=0)
    np.testing.assert_allclose(m["y"], ref.y, rtol=0, atol=0)
    assert m["Ts"] == pytest.approx(ref.dt) and m["y"].shape[1] == 4
    assert list(m["InputName"]) == list(ref.input_names)
    assert list(m["OutputName"]) == list(ref.output_names)
    assert list(m["OutputUnit"]) == list(ref.output_units) and "g" in m["OutputUnit"]
    assert list(m["InputUnit"]) == list(ref.input_units)
    s = open_session(flight.path)
    gyro = s["gyro"].data
    np.testing.assert_array_equal(m["streams"]["gyro"]["x"], gyro["x"].astype(float))
    np.testing.assert_array_equal(m["streams"]["gyro"]["host_time"], gyro["host_time"])
    assert m["units"]["gyro"]["x"] == s["gyro"].units["x"]
    assert m["Window"] == "auto" and m["ExperimentName"] == "excitation"  # sysid's default
    # a channel the session lacks: one line naming the options
    res = _run(flight.path, "--to", "mat", "--out", tmp_path / "g.mat", "--inputs", "nope")
    assert res.exit_code == 2 and res.output.count("\n") == 1 and "--inputs" in res.output
    assert not (tmp_path / "g.mat").exists()


def test_mat_of_a_log_without_the_default_window_holds_every_stream(tmp_path):
    """A log imported from elsewhere (no excitation or airborne phase): ``--to mat`` with the
    defaults refused to write anything; it writes every stream and says how to get u and y.
    Named channels or windows that are missing are still an error (above)."""
    flight = write_flight(tmp_path / "elsewhere.h5", system=known_system(), seed=4, n=800,
                          phases=[(0.0, "ground-0", "ground"), (1.0, "log", "imported")])
    out = tmp_path / "e.mat"
    res = _run(flight.path, "--to", "mat", "--out", out)
    assert res.exit_code == 0, res.output
    assert "no iddata part (u, y): pass --inputs/--outputs/--window" in res.stdout
    m = scipy.io.loadmat(out, simplify_cells=True)
    assert "u" not in m and "y" not in m and "Ts" not in m
    s = open_session(flight.path)
    np.testing.assert_array_equal(m["streams"]["motors"]["m1"], s["motors"].data["m1"])
    res = _run(flight.path, "--to", "mat", "--out", tmp_path / "f.mat", "--window", "log")
    assert res.exit_code == 0 and "no iddata" not in res.output, res.output
    assert scipy.io.loadmat(tmp_path / "f.mat")["u"].shape[1] == 4


@pytest.mark.parametrize("window", [[], ["--window", "auto"], ["--window", "airborne"]])
def test_mat_of_an_imported_log_holds_each_airborne_segment(tmp_path, window):
    """An imported log's two airborne segments: the default window was `excitation` (no
    iddata part at all), `--window auto` was refused naming a Python function, and
    `--window airborne` joined the segments with the ground between them. Each segment is now
    one experiment of iddata's multi-experiment form (u, y: 1 x 2 cell arrays), the data
    `sysid identify` identifies from."""
    flight = write_flight(tmp_path / "imp.h5", system=known_system(), seed=4, n=1500,
                          phases=[(0.0, "ground-0", "ground"), (3.0, "airborne-1", "airborne"),
                                  (12.0, "ground-1", "ground"), (15.0, "airborne-2", "airborne"),
                                  (27.0, "ground-2", "ground")])
    out = tmp_path / "imp.mat"
    res = _run(flight.path, "--to", "mat", "--out", out, *window)
    assert res.exit_code == 0, res.output
    assert res.output.strip() == f"wrote {out}"
    m = scipy.io.loadmat(out, simplify_cells=True)
    ref = load_experiments(flight.path, inputs=["motors"], outputs=["acc.z", "gyro"],
                           dt=None, detrend=None)
    assert len(ref) == 2 and list(m["ExperimentName"]) == ["airborne-1", "airborne-2"]
    for got_u, got_y, exp in zip(m["u"], m["y"], ref, strict=True):
        np.testing.assert_array_equal(got_u, exp.u)
        np.testing.assert_array_equal(got_y, exp.y)
    assert sum(len(u) for u in m["u"]) * m["Ts"] < 22.0  # 9 s + 12 s airborne, no ground


def test_parquet_round_trip_and_without_pyarrow(session, tmp_path, monkeypatch):
    import pyarrow.parquet as pq

    out = tmp_path / "pq"
    res = _run(session, "--to", "parquet", "--out", out)
    assert res.exit_code == 0, res.output
    s = open_session(session)
    table = pq.read_table(out / "gyro.parquet")
    np.testing.assert_array_equal(table.column("z").to_numpy(), s["gyro"].data["z"])
    assert table.schema.field("z").metadata[b"unit"] == s["gyro"].units["z"].encode()
    assert pq.read_table(out / "phases.parquet").column("name").to_pylist() == \
        ["takeoff", "prbs", "land"]
    monkeypatch.setitem(sys.modules, "pyarrow", None)  # not installed
    res = _run(session, "--to", "parquet", "--out", tmp_path / "none")
    assert res.exit_code == 2 and res.output.count("\n") == 1
    assert "pip install pyarrow" in res.output and not (tmp_path / "none").exists()
