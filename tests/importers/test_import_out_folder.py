"""``groundstation import`` into an ``--out`` folder that takes no files: one line, said once
(not once per log), before or at the first log."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from click.testing import CliRunner

from groundstation.cli import main as gs
from groundstation.importers import to_session


def _logs(tmp_path: Path, n: int = 3) -> list[Path]:
    """``n`` cfclient CSVs in folders of their own: ``n`` sessions to write."""
    logs = []
    for i in range(n):
        folder = tmp_path / f"log{i}"
        folder.mkdir()
        path = folder / "Gyro-20240101T10-00-00.csv"
        path.write_text("Timestamp,gyro.x\n" + "".join(f"{10 * k},{k}\n" for k in range(20)))
        logs.append(path)
    return logs


def _one_line(res) -> str:
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error")]
    assert len(errors) == 1, res.output
    assert "choose another --out folder" in errors[0]
    return errors[0]


def _import(logs: list[Path], out: Path):
    return CliRunner().invoke(gs, ["import", *map(str, logs), "--out", str(out)])


def test_an_out_folder_that_cannot_be_created_is_said_once(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    line = _one_line(_import(_logs(tmp_path), blocker / "imp"))
    assert str(blocker / "imp") in line


def test_an_unwritable_out_folder_is_refused_before_any_import(tmp_path, monkeypatch):
    out = tmp_path / "ro"
    out.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, *a, **kw: (
        False if Path(p) == out and mode & os.W_OK else real(p, mode, *a, **kw)))
    line = _one_line(_import(_logs(tmp_path), out))
    assert "not writable" in line
    assert not any(out.iterdir())


def test_a_folder_that_refuses_the_first_file_stops_the_batch(tmp_path, monkeypatch):
    calls = []

    def refuse(*a, **kw):
        calls.append(kw.get("dir"))
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(to_session.tempfile, "mkdtemp", refuse)
    line = _one_line(_import(_logs(tmp_path), tmp_path / "out"))
    assert "Permission denied" in line and len(calls) == 1


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_a_folder_without_write_permission(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    try:
        _one_line(_import(_logs(tmp_path), ro / "imp"))
    finally:
        ro.chmod(0o700)


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="POSIX FIFO")
def test_a_fifo_or_a_device_given_as_a_log_is_one_line_at_once(tmp_path):
    """Opening a FIFO waited for a writer until Ctrl-C; a device read without end."""
    fifo = tmp_path / "log00"
    os.mkfifo(fifo)
    for path in (fifo, "/dev/zero"):
        res = CliRunner().invoke(gs, ["import", str(path), "--out", str(tmp_path / "o")])
        assert res.exit_code == 2, res.output
        assert res.output.strip() == (f"error: {path}: not a regular file (a device, FIFO or "
                                      "socket); pass uSD-card deck logs, cfclient CSVs or "
                                      "folders of them")
