"""The writer's descriptor and files on every way out: an interrupt while the file is created,
a file that cannot be read back at close, a platform without ``os.fchmod`` (Windows before
Python 3.13) or that cannot replace an open file (Windows), a descriptor number reused after
close."""

from __future__ import annotations

import errno
import os
import shutil
import sys
from pathlib import Path

import h5py
import pytest

from cfsession import SessionError, SessionWriter, open_session
from cfsession.schema import log_block_spec
from cfsession.writer import standard_streams

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="/proc/self/fd")

GYRO = log_block_spec(name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"],
                      period_s=0.02)


def _open_in(folder: Path) -> list[str]:
    """The files under ``folder`` this process has open (deleted ones included)."""
    names = []
    for fd in os.listdir("/proc/self/fd"):
        try:
            name = os.readlink(f"/proc/self/fd/{fd}")
        except OSError:  # the listing's own descriptor, closed by now
            continue
        if name.startswith(str(folder)):
            names.append(name)
    return names


def _writer(path: Path, **kw) -> SessionWriter:
    w = SessionWriter(path, streams=[GYRO, *standard_streams()], flush_interval=0.0, **kw)
    w.extend("gyro", [(k * 0.02, 20 * k, 0.1, 0.2, float(k)) for k in range(200)])
    return w


def test_an_interrupt_while_the_file_is_created_leaves_no_file_open_or_behind(tmp_path,
                                                                             monkeypatch):
    real, calls = os.pwrite, []

    def pwrite(fd, data, pos):  # Ctrl-C inside HDF5's first write: completed, raised after
        calls.append(pos)
        if len(calls) == 1:
            raise KeyboardInterrupt
        return real(fd, data, pos)

    monkeypatch.setattr(os, "pwrite", pwrite)
    with pytest.raises(KeyboardInterrupt):
        SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()])
    assert calls and not list(tmp_path.iterdir())
    assert _open_in(tmp_path) == []


def test_a_deleted_file_that_cannot_be_read_back_is_one_line(tmp_path, monkeypatch):
    out = tmp_path / "out"
    w = _writer(out / "s.h5")
    shutil.rmtree(out)

    real = os.pread

    def pread(fd, n, pos):  # the whole file cannot be read back (HDF5's own reads can)
        if pos == 0 and n > 4096:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real(fd, n, pos)

    monkeypatch.setattr(os, "pread", pread)
    with pytest.raises(SessionError, match=r"Input/output error.*the session is lost") as err:
        w.close()
    assert "\n" not in str(err.value)
    assert _open_in(tmp_path) == []


def test_without_fchmod_the_session_is_still_compressed_with_its_mode(tmp_path, monkeypatch):
    monkeypatch.delattr(os, "fchmod")
    old = os.umask(0o027)
    try:
        path = _writer(tmp_path / "s.h5").close()
    finally:
        os.umask(old)
    with h5py.File(path, "r") as f:
        assert f["gyro/data"].compression == "gzip"
    assert os.stat(path).st_mode & 0o777 == 0o640
    assert len(open_session(path)["gyro"]) == 200


@pytest.mark.parametrize("from_memory", [False, True])
def test_the_session_file_is_closed_before_it_is_replaced(tmp_path, monkeypatch, from_memory):
    """Windows refuses to replace a file that is open: the compressed copy (or the session saved
    from memory after a failed write) replaces the file only once the writer has closed it."""
    w = _writer(tmp_path / "s.h5")
    if from_memory:
        w._io._to_memory(OSError(errno.EIO, os.strerror(errno.EIO)))
        w.extend("gyro", [(k * 0.02, 20 * k, 0.1, 0.2, float(k)) for k in range(200, 300)])
    real, still_open = os.replace, []

    def replace(src, dst):
        still_open.extend(n for n in _open_in(tmp_path) if n == str(dst))
        return real(src, dst)

    monkeypatch.setattr(os, "replace", replace)
    assert w.close() == tmp_path / "s.h5"
    assert still_open == []
    assert len(open_session(tmp_path / "s.h5")["gyro"]) == (300 if from_memory else 200)


def test_a_descriptor_number_reused_after_close_is_never_written(tmp_path):
    w = _writer(tmp_path / "s.h5")
    number = w._io.fd
    w.close()
    other = tmp_path / "other.bin"
    other.write_bytes(b"another file")
    fd = os.open(other, os.O_RDWR)
    try:
        if fd != number:
            os.dup2(fd, number)
        w._io.seek(0)
        w._io.write(b"late write")  # HDF5 retrying a close at exit
    finally:
        os.close(fd)
        if fd != number:
            os.close(number)
    assert other.read_bytes() == b"another file"
