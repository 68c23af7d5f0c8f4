"""A disk that fills, a file size limit or a failing write while a session is written: never a
crash, a hang or a traceback; the rows that reached the disk stay readable, and the writer says
what happened in one line (``SessionWriter.trouble``, ``notes``, ``saved_until``).

The file size limit is real (``RLIMIT_FSIZE`` in a child process: writes past it fail with
EFBIG, as under ``ulimit -f``); a full disk is injected at the system call (``os.pwrite``,
``os.posix_fallocate``, ``os.fsync``), where ENOSPC would come from."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest

import cfsession.writer as writer_mod
from cfsession import SessionError, SessionWriter, open_session
from cfsession.schema import log_block_spec
from cfsession.writer import standard_streams

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX resource limits")

GYRO = log_block_spec(name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"],
                      period_s=0.02)

CHILD = textwrap.dedent(
    """
    import resource, sys
    import numpy as np
    from cfsession.writer import SessionWriter, standard_streams
    from cfsession.schema import log_block_spec

    path, reserve, limit, rows, after = sys.argv[1], *map(int, sys.argv[2:6])
    gyro = log_block_spec(name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"],
                          period_s=0.02)
    kw = {"reserve": reserve} if reserve else {}
    w = SessionWriter(path, streams=[gyro, *standard_streams()], flush_interval=1e9, **kw)
    resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))  # ulimit -f, once created
    rng = np.random.default_rng(1)
    k, told = 0, None
    while k < rows and (told is None or k < told + after):  # the landing after the trouble
        x, y = rng.normal(size=2)  # noise: gzip cannot make the file much smaller
        w.append("gyro", (k * 0.02, 20 * k, x, y, float(k)))
        k += 1
        if k % 50 == 0:
            w.flush()
            if told is None and getattr(w, "trouble", ""):
                told = k
                print("trouble at", k, w.trouble, flush=True)
    try:
        w.close(duration_s=k * 0.02)
    except ValueError as exc:  # SessionError: the file holds part of the session
        w.notes.append(str(exc))
    print("closed", k, w.path, w.saved_until, *w.notes, sep="|", flush=True)
    """
)


def _run_child(tmp_path, *, reserve: int, limit: int, rows: int,
               after: int = 150) -> tuple[str, str]:
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    out = tmp_path / "s.h5"
    proc = subprocess.run([sys.executable, str(script), str(out), str(reserve), str(limit),
                           str(rows), str(after)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-3000:])  # -11: h5py crashed
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]
    return proc.stdout, proc.stderr


def _sequence_ok(session) -> int:
    """Rows of the gyro stream, checked to be the first ones written, whole and in order."""
    z = session["gyro"].data["z"]
    np.testing.assert_array_equal(z, np.arange(len(z)))
    return len(z)


def test_a_file_size_limit_without_a_reserve_keeps_what_reached_the_disk(tmp_path):
    """Writes past the limit fail (EFBIG); the rest of the session stays in memory and does not
    fit compressed either: the file holds what reached it, readable, and says until when."""
    stdout, _ = _run_child(tmp_path, reserve=0, limit=40_000, rows=6000, after=6000)
    trouble = next(ln for ln in stdout.splitlines() if ln.startswith("trouble"))
    assert "file size limit reached" in trouble and "40000 bytes" in trouble
    closed = next(ln for ln in stdout.splitlines() if ln.startswith("closed")).split("|")
    saved_until = float(closed[3])
    assert "holds the session up to" in closed[4] and "\n" not in closed[4]
    s = open_session(tmp_path / "s.h5")
    n = _sequence_ok(s)
    assert n >= 100 and s["gyro"].time.max() >= saved_until
    assert s.problems  # flagged: the writer did not close it
    assert os.path.getsize(tmp_path / "s.h5") <= 40_000


def test_a_file_size_limit_with_a_reserve_is_told_while_the_landing_still_fits(tmp_path):
    """The reserve cannot be renewed (the limit): ``trouble`` says so, and the 150 rows written
    after it (the landing) still reach the file, which closes cleanly and whole."""
    stdout, _ = _run_child(tmp_path, reserve=16 << 10, limit=100_000, rows=20_000)
    trouble = next(ln for ln in stdout.splitlines() if ln.startswith("trouble"))
    assert "file size limit reached" in trouble and "(ulimit -f)" in trouble
    closed = next(ln for ln in stdout.splitlines() if ln.startswith("closed")).split("|")
    written = int(closed[1])
    assert closed[3] == "None" and written < 20_000
    s = open_session(tmp_path / "s.h5")
    assert s.closed_cleanly and not s.problems
    assert _sequence_ok(s) == written


# --------------------------------------------------------------- injected at the system call
class _Disk:
    """``os.pwrite`` / ``os.posix_fallocate`` that fail with ENOSPC while :attr:`full`, but
    for the files (inode numbers) in :attr:`spare`."""

    def __init__(self, monkeypatch) -> None:
        self.full, self.spare = False, set()
        self._pwrite, self._fallocate = os.pwrite, os.posix_fallocate
        monkeypatch.setattr(writer_mod.os, "pwrite", self.pwrite)
        monkeypatch.setattr(writer_mod.os, "posix_fallocate", self.fallocate)

    def _refuse(self, fd: int) -> None:
        if self.full and os.fstat(fd).st_ino not in self.spare:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def pwrite(self, fd, data, pos):
        self._refuse(fd)
        return self._pwrite(fd, data, pos)

    def fallocate(self, fd, offset, length):
        self._refuse(fd)
        return self._fallocate(fd, offset, length)


def _fill(w: SessionWriter, k0: int, n: int) -> None:
    for k in range(k0, k0 + n):
        w.append("gyro", (k * 0.02, 20 * k, 0.1, 0.2, float(k)))
        if k % 50 == 49:
            w.flush()


def test_a_failed_write_goes_on_in_memory_and_is_saved_whole_when_there_is_room(
        tmp_path, monkeypatch):
    disk = _Disk(monkeypatch)
    w = SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()],
                      flush_interval=1e9)
    _fill(w, 0, 500)
    disk.full = True
    _fill(w, 500, 500)  # every write fails: nothing raised, nothing lost
    assert w.trouble == f"disk full: no room left in {tmp_path} (No space left on device)"
    disk.full = False  # another process freed space before the close
    assert w.close(duration_s=20.0) == tmp_path / "s.h5"
    assert w.saved_until is None and "kept in memory" in w.notes[0]
    s = open_session(tmp_path / "s.h5")
    assert s.closed_cleanly and not s.problems and _sequence_ok(s) == 1000


def failed_midway(tmp_path, monkeypatch) -> tuple[SessionWriter, _Disk]:
    """A session of 1000 rows of which the first 500 reached the disk before it filled, the
    rest kept in memory; the disk still full."""
    disk = _Disk(monkeypatch)
    w = SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()],
                      flush_interval=1e9)
    _fill(w, 0, 500)
    disk.full = True
    _fill(w, 500, 500)
    return w, disk


def test_a_disk_that_stays_full_keeps_the_rows_written_before(tmp_path, monkeypatch):
    w, _ = failed_midway(tmp_path, monkeypatch)
    with pytest.raises(SessionError, match=r"holds the session up to 9\.9 s only") as err:
        w.close(duration_s=20.0)
    assert "disk full: no room left in" in str(err.value) and "\n" not in str(err.value)
    assert w.saved_until == pytest.approx(9.98) and w.path == tmp_path / "s.h5"
    s = open_session(tmp_path / "s.h5")
    assert _sequence_ok(s) == 500 and s.problems


def test_nothing_reached_the_disk_is_one_line(tmp_path, monkeypatch):
    disk = _Disk(monkeypatch)
    w = SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()],
                      flush_interval=1e9)
    disk.full = True
    _fill(w, 0, 100)
    with pytest.raises(SessionError, match=r"no row reached .* its data are lost") as err:
        w.close()
    assert "\n" not in str(err.value)


def test_a_disk_full_at_creation_is_refused_with_a_reserve(tmp_path, monkeypatch):
    disk = _Disk(monkeypatch)
    disk.full = True
    with pytest.raises(SessionError, match=r"disk full: no room left in .*needs 32 KiB"):
        SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()], reserve=16 << 10)
    assert not list(tmp_path.iterdir())


def test_a_full_disk_while_compressing_keeps_the_file_uncompressed(tmp_path, monkeypatch,
                                                                  caplog):
    disk = _Disk(monkeypatch)
    w = SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()])
    _fill(w, 0, 500)
    disk.full = True  # room for the session, none for its copy
    disk.spare = {os.fstat(w._io.fd).st_ino}
    with caplog.at_level("WARNING", logger="cfsession.writer"):
        assert w.close() == tmp_path / "s.h5"
    (warning,) = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    assert "could not compress" in warning and "No space left on device" in warning
    assert "\n" not in warning
    assert [p.name for p in tmp_path.iterdir()] == ["s.h5"]  # the temporary file removed
    s = open_session(tmp_path / "s.h5")
    assert s.closed_cleanly and not s.problems and _sequence_ok(s) == 500
    with h5py.File(tmp_path / "s.h5", "r") as f:
        assert f["gyro/data"].compression is None


def test_a_failing_fsync_is_trouble_not_a_thread_traceback(tmp_path, monkeypatch):
    def eio(fd):
        raise OSError(errno.EIO, os.strerror(errno.EIO))

    monkeypatch.setattr(writer_mod.os, "fsync", eio)
    w = SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()],
                      fsync_interval=0.0, flush_interval=0.0, compress_on_close=False)
    _fill(w, 0, 60)
    w._join_fsync()
    assert w.trouble == f"cannot write in {tmp_path} (Input/output error)"
    w.close()
    assert _sequence_ok(open_session(tmp_path / "s.h5")) == 60
