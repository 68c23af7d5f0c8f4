"""What ``close`` does when the usual way of saving a session has no room: a session kept in
memory after a failed write goes over the partial file in place when there is no room for a
copy beside it (and the partial file is kept as it was when that fails too); a file whose disk
refused its reserve is still compressed when the free space holds the compressed copy; a read
the disk refuses while writing is a failed write's path, never an error out of HDF5.

A full disk is injected at the system call (``test_disk_full._Disk``); the free space
``statvfs`` reports is injected through :func:`cfsession.copies.free_bytes`."""

from __future__ import annotations

import errno
import os
import sys

import h5py
import pytest

import cfsession.copies as copies
from cfsession import SessionError, SessionWriter, open_session
from cfsession.writer import standard_streams

from .test_disk_full import GYRO, _Disk, _fill, _sequence_ok, failed_midway

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="POSIX system calls")


def _failed_midway(tmp_path, monkeypatch) -> tuple[SessionWriter, _Disk]:
    """A session of 1000 rows of which the first 500 reached the disk, the rest in memory;
    the disk still full, but for the partial file's own room."""
    w, disk = failed_midway(tmp_path, monkeypatch)
    assert w._io.memory is not None
    disk.spare = {os.fstat(w._io.fd).st_ino}  # its room is held; no other file gets any
    return w, disk


def test_no_room_for_a_copy_saves_the_session_over_the_partial_file(tmp_path, monkeypatch):
    w, _ = _failed_midway(tmp_path, monkeypatch)
    assert w.close(duration_s=20.0) == tmp_path / "s.h5" and w.saved_until is None
    (note,) = w.notes
    assert note.startswith("disk full: no room left in") and "kept in memory" in note
    assert "over the partial file, no room being left for a copy beside it" in note
    assert [p.name for p in tmp_path.iterdir()] == ["s.h5"]
    s = open_session(tmp_path / "s.h5")
    assert s.closed_cleanly and not s.problems and _sequence_ok(s) == 1000
    with h5py.File(tmp_path / "s.h5", "r") as f:
        assert f["gyro/data"].compression == "gzip"


def test_a_session_too_big_for_the_partial_file_leaves_it_as_it_was(tmp_path, monkeypatch):
    w, _ = _failed_midway(tmp_path, monkeypatch)
    before = (tmp_path / "s.h5").stat().st_size
    monkeypatch.setattr(copies, "free_bytes", lambda folder: 0)
    real = copies.compressed_image
    monkeypatch.setattr(copies, "compressed_image", lambda image: real(image) + bytes(1 << 20))
    monkeypatch.setattr("cfsession.saving.compressed_image", copies.compressed_image)
    with pytest.raises(SessionError, match=r"holds the session up to 9\.9 s only") as err:
        w.close()
    assert "over the partial file: the compressed session" in str(err.value)
    assert "does not fit" in str(err.value) and "\n" not in str(err.value)
    assert (tmp_path / "s.h5").stat().st_size >= before
    assert _sequence_ok(open_session(tmp_path / "s.h5")) == 500


def test_a_failure_writing_over_the_partial_file_writes_it_back(tmp_path, monkeypatch):
    w, _ = _failed_midway(tmp_path, monkeypatch)
    real, failed = os.fsync, []

    def fsync(fd):
        if not failed and fd != w._io.fd and w._io.fd == -1:  # the first after writing over
            failed.append(fd)
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    with pytest.raises(SessionError, match=r"up to 9\.9 s only .*Input/output error"):
        w.close()
    assert failed
    s = open_session(tmp_path / "s.h5")
    assert _sequence_ok(s) == 500 and s.problems


def test_a_failed_write_back_says_the_partial_file_is_damaged(tmp_path, monkeypatch):
    """A file system that copies on write (btrfs, ZFS) needs new room to write over a file:
    half the compressed session reaches it, then the disk is full, writing the old bytes back
    too. The error never claims the file holds the flight up to some time."""
    w, _ = _failed_midway(tmp_path, monkeypatch)
    ino, real, calls = (tmp_path / "s.h5").stat().st_ino, os.pwrite, []

    def pwrite(fd, data, pos):
        if w._io.fd == -1 and len(data) > 1000 and os.fstat(fd).st_ino == ino:  # in place
            calls.append(len(data))
            if len(calls) == 1:
                return real(fd, bytes(data)[: len(data) // 2], pos)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, data, pos)

    monkeypatch.setattr(os, "pwrite", pwrite)
    with pytest.raises(SessionError) as err:
        w.close()
    text = str(err.value)
    assert len(calls) >= 3 and "\n" not in text  # the new image, then the old one back
    assert "holds the session up to" not in text and w.saved_until is None
    assert text.endswith("writing the partial file back failed too (No space left on "
                         f"device): {tmp_path / 's.h5'} is damaged, its data are lost")
    assert "over the partial file: No space left on device" in text


def test_writing_in_place_syncs_the_new_bytes_before_cutting_the_old_ones_off(
        tmp_path, monkeypatch):
    path = tmp_path / "f"
    path.write_bytes(bytes(10000))
    done: list[str] = []
    for name in ("pwrite", "fsync", "ftruncate"):
        real = getattr(os, name)
        monkeypatch.setattr(os, name, lambda *a, _n=name, _r=real: (done.append(_n), _r(*a))[1])
    st = path.stat()
    copies.overwrite_in_place(path, b"new" * 100, ids=(st.st_dev, st.st_ino))
    assert done == ["pwrite", "fsync", "ftruncate", "fsync"]
    assert path.read_bytes() == b"new" * 100


def _reserve_refused(monkeypatch) -> None:
    """``posix_fallocate`` refuses (ENOSPC) room beyond a file's first 64 KiB."""
    real = os.posix_fallocate

    def fallocate(fd, offset, length):
        if offset + length > 64 << 10:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(fd, offset, length)

    monkeypatch.setattr(os, "posix_fallocate", fallocate)


def _reserved_writer(tmp_path) -> SessionWriter:
    w = SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()],
                      flush_interval=1e9, reserve=16 << 10)
    _fill(w, 0, 3000)
    assert w.disk_full and w._io.memory is None
    return w


def test_a_refused_reserve_is_compressed_at_close_when_the_free_space_holds_it(
        tmp_path, monkeypatch):
    _reserve_refused(monkeypatch)
    w = _reserved_writer(tmp_path)
    w.close()
    with h5py.File(tmp_path / "s.h5", "r") as f:
        assert f["gyro/data"].compression == "gzip"
    assert _sequence_ok(open_session(tmp_path / "s.h5")) == 3000


def test_no_free_space_for_the_compressed_copy_keeps_the_file_and_says_so(tmp_path, monkeypatch,
                                                                         caplog):
    _reserve_refused(monkeypatch)
    monkeypatch.setattr(copies, "free_bytes", lambda folder: 10 << 10)
    w = _reserved_writer(tmp_path)
    with caplog.at_level("INFO", logger="cfsession.writer"):
        w.close()
    (line,) = [r.getMessage() for r in caplog.records if "not compressed" in r.getMessage()]
    assert line.startswith(f"{tmp_path / 's.h5'} not compressed: the disk is full (10 KiB free, "
                           "the compressed copy needs ")
    assert [p.name for p in tmp_path.iterdir()] == ["s.h5"]
    with h5py.File(tmp_path / "s.h5", "r") as f:
        assert f["gyro/data"].compression is None
    assert _sequence_ok(open_session(tmp_path / "s.h5")) == 3000


def test_a_read_the_disk_refuses_is_trouble_not_an_error_out_of_hdf5(tmp_path, monkeypatch):
    w = SessionWriter(tmp_path / "s.h5", streams=[GYRO, *standard_streams()],
                      flush_interval=1e9)
    _fill(w, 0, 500)
    real = os.pread

    def pread(fd, n, pos):  # HDF5's read fails; reading the file back in blocks does not
        if n == 100:
            raise OSError(errno.EIO, os.strerror(errno.EIO))
        return real(fd, n, pos)

    monkeypatch.setattr(os, "pread", pread)
    w._io.seek(0)
    assert len(w._io.read(100)) == 100  # as HDF5 reads (before: the OSError reached HDF5)
    assert w.trouble == f"cannot write in {tmp_path} (Input/output error)"
    _fill(w, 500, 500)
    w.close()
    assert "kept in memory" in w.notes[0]
    s = open_session(tmp_path / "s.h5")
    assert s.closed_cleanly and _sequence_ok(s) == 1000
