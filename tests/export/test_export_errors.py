"""``groundstation export``'s user errors: one line saying what to do, the same for every
format (an unwritable folder, a missing ``--to``); a missing folder is made, as ``import``'s."""

from __future__ import annotations

import os
import pathlib

import pytest
from click.testing import CliRunner

from groundstation.cli import main
from tests.viz.sessions import write_session


def _run(*args):
    return CliRunner().invoke(main, ["export", *map(str, args)])


def _one_line(res) -> str:
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    assert "Traceback" not in res.output and "\t" not in res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.output
    return lines[0]


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return write_session(tmp_path_factory.mktemp("export") / "flight.h5")


@pytest.fixture
def read_only(tmp_path, monkeypatch):
    """A folder the user may not write into (``os.access`` says so; root may write anywhere,
    so the test cannot rely on the mode bits alone)."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access

    def access(path, mode, *a, **kw):
        if pathlib.Path(path).resolve() == ro.resolve() and mode & os.W_OK:
            return False
        return real(path, mode, *a, **kw)

    monkeypatch.setattr(os, "access", access)
    return ro


@pytest.mark.parametrize(("to", "out"), [("csv", "csv"), ("parquet", "pq"), ("mat", "f.mat")])
def test_an_unwritable_folder_is_one_line_the_same_for_every_format(session, read_only, to,
                                                                      out):
    window = ["--window", "all"] if to == "mat" else []  # a mat-only option
    line = _one_line(_run(session, "--to", to, "--out", read_only / out, *window))
    assert f"folder {str(read_only)!r} is not writable" in line and "-h" in line
    assert not any(read_only.iterdir())


@pytest.mark.parametrize(("to", "out"), [("csv", "exp/deep/csv"), ("mat", "exp/deep/pad.mat")])
def test_a_missing_folder_is_made_as_import_makes_its_own(session, tmp_path, to, out):
    """``export --to mat --out exp/pad.mat`` refused "folder 'exp' does not exist; create it
    first" while ``import --out`` makes its folder."""
    res = _run(session, "--to", to, "--out", tmp_path / out)
    assert res.exit_code == 0, res.output
    made = tmp_path / out
    assert (any(made.iterdir()) if to == "csv" else made.stat().st_size > 0)


@pytest.mark.parametrize(("to", "out"), [("csv", "new/csv"), ("mat", "new/f.mat")])
def test_a_missing_folder_under_an_unwritable_one_is_refused_first(session, read_only, to, out):
    line = _one_line(_run(session, "--to", to, "--out", read_only / out))
    assert f"folder {str(read_only)!r} is not writable" in line
    assert not any(read_only.iterdir())


def test_a_missing_folder_named_like_a_file_is_not_made(session, tmp_path):
    line = _one_line(_run(session, "--to", "mat", "--out", tmp_path / "exp.mat" / "pad.mat"))
    assert "named like a file" in line and not (tmp_path / "exp.mat").exists()


@pytest.mark.parametrize("to", ["csv", "parquet"])
def test_an_existing_unwritable_output_folder_is_named(session, read_only, to):
    line = _one_line(_run(session, "--to", to, "--out", read_only))
    assert f"folder {str(read_only)!r} is not writable" in line


def test_a_file_refused_while_writing_names_its_folder(session, tmp_path, monkeypatch):
    out = tmp_path / "csv"
    real_open = pathlib.Path.open

    def refusing_open(self, mode="r", *a, **kw):
        if "w" in mode and self.parent == out:
            raise PermissionError(13, "Permission denied", str(self))
        return real_open(self, mode, *a, **kw)

    monkeypatch.setattr(pathlib.Path, "open", refusing_open)
    line = _one_line(_run(session, "--to", "csv", "--out", out))
    assert f"folder {str(out)!r} is not writable" in line


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_a_folder_without_write_permission(session, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        line = _one_line(_run(session, "--to", "csv", "--out", ro / "csv"))
    finally:
        ro.chmod(0o700)
    assert f"folder {str(ro)!r} is not writable" in line


def test_a_missing_format_lists_the_choices_on_one_line(session):
    line = _one_line(_run(session))
    assert "Missing option '--to'" in line and "csv, mat or parquet" in line


@pytest.mark.parametrize("to", ["csv", "parquet"])
def test_standard_output_as_the_folder_is_refused(session, tmp_path, monkeypatch, to):
    """`--out -` is the usual name for standard output; export wrote a folder named '-'."""
    monkeypatch.chdir(tmp_path)
    msg = _one_line(_run(session, "--to", to, "--out", "-"))
    assert "'-' (standard output)" in msg and "give a folder" in msg
    assert not (tmp_path / "-").exists()


def test_fly_refuses_standard_output_as_its_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    msg = _one_line(CliRunner().invoke(main, ["fly", "hover-check", "--uri",
                                              "sim://0?speed=inf", "--out", "-"]))
    assert msg.startswith("error: --out -: sessions are files in a folder")
    assert not (tmp_path / "-").exists()


def test_a_grid_far_finer_than_the_log_is_one_line_not_an_allocation(session, tmp_path):
    """``--dt 0.0000001`` on a 50 Hz log asked numpy for 61 GiB and ended in a traceback."""
    line = _one_line(_run(session, "--to", "mat", "--window", "all", "--dt", "1e-7",
                          "--out", tmp_path / "tiny.mat"))
    assert line == (f"error: the iddata part (u, y) cannot be built: {session}: dt=1e-07 s is "
                    "100000x finer than the logged period 0.01 s; pass dt >= 1e-05 (at most "
                    "1000x finer)")
    assert not (tmp_path / "tiny.mat").exists()


@pytest.mark.parametrize("to", ["csv", "parquet"])
@pytest.mark.parametrize("option", [["--dt", "0.01"], ["--window", "nosuch"],
                                    ["--inputs", "motors"]])
def test_mat_only_options_with_another_format_are_refused(session, tmp_path, to, option):
    """They shape the .mat's iddata only; csv and parquet ignored them and exited 0."""
    line = _one_line(_run(session, "--to", to, *option, "--out", tmp_path / "x"))
    assert line.startswith(f"error: Invalid value for '{option[0]}': for --to mat only (its "
                           f"iddata u, y); --to {to} writes every stream whole")
    assert not (tmp_path / "x").exists()


def test_a_nan_grid_period_is_refused(session, tmp_path):
    line = _one_line(_run(session, "--to", "mat", "--dt", "nan", "--out", tmp_path / "x.mat"))
    assert "'nan' is not a finite number" in line


@pytest.mark.parametrize("to", ["csv", "mat"])
def test_a_full_disk_leaves_no_file_cut_short_and_names_the_file(session, tmp_path,
                                                                monkeypatch, to):
    """A disk that filled mid-file left a cut-short STREAM.csv (or .mat) looking whole, and
    the error said only "an output file (it may be cut short)"."""
    import csv

    import scipy.io

    def filling(fh, *args, **kwargs):
        fh.write("x" * 1000)
        raise OSError(28, "No space left on device")

    if to == "csv":
        real = csv.writer

        def writer(fh, *args, **kwargs):
            w = real(fh, *args, **kwargs)
            return w if "gyro" not in fh.name else type("Full", (), {
                "writerow": w.writerow, "writerows": lambda self, rows: filling(fh)})()

        monkeypatch.setattr(csv, "writer", writer)
        out, stopped = tmp_path / "csv", tmp_path / "csv" / "gyro.csv"
    else:
        monkeypatch.setattr(scipy.io, "savemat",
                            lambda path, *a, **kw: filling(open(path, "w")))  # noqa: SIM115
        out = stopped = tmp_path / "f.mat"
    res = _run(session, "--to", to, "--out", out, *(["--window", "all"] if to == "mat" else []))
    line = _one_line(res)
    assert line == f"error: cannot write {stopped}: No space left on device"
    assert not stopped.exists()
    left = sorted(p.name for p in tmp_path.rglob("*") if p.is_file())
    assert not [n for n in left if n.endswith(".part") or n == stopped.name], left


@pytest.mark.parametrize(("to", "out"), [("csv", "flight.csv"), ("parquet", "flight.parquet"),
                                         ("csv", "flight.json"), ("parquet", "flight.rrd")])
def test_a_file_name_for_a_folder_export_is_one_line(session, tmp_path, to, out):
    """`--to csv --out flight.csv` made a folder named flight.csv of eleven CSV files (and
    `--out flight.json`, whose suffix the check did not know, still does)."""
    line = _one_line(_run(session, "--to", to, "--out", tmp_path / out))
    assert (f"{str(tmp_path / out)!r} names a file, but --to {to} writes one file per stream "
            f"into a folder; give a folder (e.g. {str(tmp_path / 'flight')!r})") in line
    assert not (tmp_path / out).exists()
