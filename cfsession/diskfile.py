"""The file a session is written through, and what the disk may refuse it.

HDF5 writes a session through :class:`SessionFile` (h5py's ``fileobj`` driver over one
descriptor), never straight to the disk, so that a write the disk refuses never reaches HDF5:
h5py cannot close a file whose writes keep failing (it retried at exit and crashed the
interpreter). The file keeps ``reserve`` bytes allocated beyond what it has written
(:data:`RESERVE_BYTES` for a flight) and goes on in memory once a write fails
(``docs/session-format.md``, "When the disk fills"). :func:`disk_problem` names a refusal in
one line; :func:`check_room` asks for a session's starting room before a flight.

Used by :mod:`cfsession.writer` (the session) and :mod:`cfsession.saving` (the compressed copy
written at close).
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
from pathlib import Path
from typing import Any

from cfsession.errors import SessionError

__all__ = ["OPEN_FLAGS", "RESERVE_BYTES", "SessionFile", "check_room", "check_writable",
           "disk_problem", "read_all", "write_all"]

log = logging.getLogger("cfsession.writer")  # the writer's file: logged as the writer

OPEN_FLAGS = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_BINARY", 0)
"""Added to every ``os.open`` of a session's files: never through a symbolic link, and binary
on Windows (where a descriptor opened without ``O_BINARY`` writes every ``\\n`` as ``\\r\\n``)."""

RESERVE_BYTES = 256 << 10
"""Disk space a flight's session keeps allocated beyond what it has written (``reserve`` of
:class:`~cfsession.writer.SessionWriter`, used by the flight recorder): once the disk, a quota
or the file size limit (``ulimit -f``) will not give more,
:attr:`~cfsession.writer.SessionWriter.trouble` says so while this much room is still there for
the landing (a few seconds need about 10 KiB a second)."""

_FULL = {errno.ENOSPC: "disk full", errno.EDQUOT: "disk quota exceeded",
         errno.EFBIG: "file size limit reached"}
"""Errors that mean no more room (and nothing else wrong): the flight can land into the reserve."""


def _fsize_limit() -> int | None:
    """The soft file size limit (``ulimit -f``) in bytes, ``None`` when there is none."""
    try:
        import resource
    except ImportError:  # not POSIX
        return None
    soft = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
    return None if soft == resource.RLIM_INFINITY else int(soft)


def disk_problem(exc: OSError, folder: Path, *, wanted: int = 0) -> str:
    """One line for a write (or an allocation of ``wanted`` bytes) in ``folder`` that the disk
    refused."""
    if exc.errno == errno.EFBIG:
        limit = _fsize_limit()
        if limit is not None:
            return (f"file size limit reached writing in {folder}: a file may not grow past "
                    f"{limit} bytes (ulimit -f)")
        return f"file too large for the file system of {folder}"
    if exc.errno in _FULL:
        room = f" for the session's next {wanted >> 10} KiB" if wanted else ""
        return f"{_FULL[exc.errno]}: no room left in {folder}{room} ({exc.strerror or exc})"
    return f"cannot write in {folder} ({exc.strerror or exc})"


def check_room(path: str | os.PathLike[str], nbytes: int = 2 * RESERVE_BYTES) -> None:
    """Allocate ``nbytes`` in the existing, empty file ``path`` (a probe: its caller removes
    it) or say in one line (:class:`SessionError`) that the disk, a quota or the file size
    limit will not give them."""
    fd = os.open(path, os.O_WRONLY | OPEN_FLAGS)
    try:
        _fallocate(fd, 0, nbytes)
    except OSError as exc:
        if exc.errno in _FULL:
            raise SessionError(f"{disk_problem(exc, Path(path).parent)}; a flight's session "
                               f"needs {nbytes >> 10} KiB to start") from None
        log.debug("cannot allocate in %s: %s", path, exc)  # no allocation on this file system
    finally:
        os.close(fd)


def check_writable(path: str | os.PathLike[str]) -> None:
    """Fail early (one line) if a session cannot be created at ``path``."""
    p = Path(path)
    if p.exists():
        raise SessionError(f"{p}: already exists; choose another output path")
    parent = p.parent if str(p.parent) else Path(".")
    probe = parent
    while not probe.exists():
        probe = probe.parent
    if not os.access(probe, os.W_OK):
        raise SessionError(f"{parent}: not writable; choose another --out folder")


def _pwrite(fd: int, data: memoryview, pos: int) -> int:
    if hasattr(os, "pwrite"):
        return os.pwrite(fd, data, pos)
    os.lseek(fd, pos, os.SEEK_SET)  # Windows: one thread writes
    return os.write(fd, data)


def _pread(fd: int, n: int, pos: int) -> bytes:
    if hasattr(os, "pread"):
        return os.pread(fd, n, pos)
    os.lseek(fd, pos, os.SEEK_SET)
    return os.read(fd, n)


def write_all(fd: int, data: bytes | bytearray | memoryview, *, at: int = 0,
              written: list[int] | None = None) -> None:
    """All of ``data`` into ``fd`` from offset ``at``, in positioned writes (a short write goes
    on; none at all is ENOSPC). ``written[0]``: the bytes of ``data`` written so far."""
    view, done = memoryview(data).cast("B"), 0
    while done < len(view):
        n = _pwrite(fd, view[done:], at + done)
        if n <= 0:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        done += n
        if written is not None:
            written[0] = done


def read_all(fd: int, size: int) -> bytes:
    """Up to ``size`` bytes of ``fd`` from its start (fewer at its end)."""
    parts, got = [], 0
    while got < size:
        part = _pread(fd, size - got, got)
        if not part:
            break
        parts.append(part)
        got += len(part)
    return b"".join(parts)


def _fallocate(fd: int, offset: int, length: int) -> None:
    if not hasattr(os, "posix_fallocate"):  # macOS, Windows: no reserve
        raise OSError(errno.EOPNOTSUPP, "posix_fallocate is not available")
    os.posix_fallocate(fd, offset, length)


class SessionFile:
    """What HDF5 writes a session through (h5py's ``fileobj`` driver): positioned reads and
    writes on one descriptor, so that no failing write ever reaches HDF5 (h5py cannot close a
    file whose writes keep failing: it retried for ever at exit and crashed the interpreter).

    * ``reserve`` bytes beyond the end written are kept allocated (``posix_fallocate``, a
      reserve's worth at a time). When the disk, a quota or the file size limit refuses more,
      :attr:`problem` is set and writing goes on into what is allocated.
    * A write (or a read back) that fails all the same (another process took the space, an
      I/O error) sets :attr:`problem` and :attr:`failed`; the file's bytes are read into
      memory (zeros for what cannot be read) and everything from then on (that write
      included) goes to :attr:`memory`, so HDF5 finishes the file there and the writer can
      save it whole at close if there is room again.
    * Past the end reads as zeros, as HDF5's own drivers read it.
    * A signal handler that raises (Ctrl-C) while HDF5 is inside one of these calls does not
      interrupt it: the call completes (each is idempotent) and :meth:`raise_interrupt`
      raises the exception once HDF5 has returned.
    * :meth:`close` closes the descriptor once; :attr:`fd` is ``-1`` from then on, so nothing
      written later (HDF5 retrying a close at exit) can reach a file that reuses its number.
    """

    def __init__(self, fd: int, *, reserve: int = 0) -> None:
        self.fd, self.reserve = fd, reserve
        self.pos = 0
        self.size = 0  # HDF5's end of file
        self.disk_size = 0  # bytes the descriptor's file has (written or allocated)
        self.memory: bytearray | None = None
        self.problem: OSError | None = None  # the first refusal (allocation or write)
        self.refused = 0  # bytes the allocation that was the first refusal asked for
        self.failed: OSError | None = None  # the write that failed: memory since
        self.interrupt: BaseException | None = None

    # --------------------------------------------- the file object h5py's fileobj driver uses
    def seek(self, offset: int, whence: int = os.SEEK_SET) -> int:
        base = {os.SEEK_SET: 0, os.SEEK_CUR: self.pos, os.SEEK_END: self.size}[whence]
        self.pos = base + offset
        return self.pos

    def tell(self) -> int:
        return self.pos

    def read(self, n: int = -1) -> bytes:
        n = max(self.size - self.pos, 0) if n is None or n < 0 else n
        data = self._completed(self._read_back, self.pos, n)
        self.pos += n
        return data

    def write(self, data: bytes | bytearray | memoryview) -> int:
        size = len(data)
        self._completed(self._write, self.pos, data)
        self.pos += size
        self.size = max(self.size, self.pos)
        return size

    def truncate(self, size: int | None = None) -> int:
        size = self.pos if size is None else size
        self._completed(self._resize, size)
        self.size = size
        return size

    def flush(self) -> None:
        """Nothing buffered here (the writer ``fsync``-s the descriptor itself)."""

    # ---------------------------------------------------------------------- the work
    def raise_interrupt(self) -> None:
        """Raise what a signal handler raised inside one of HDF5's calls (see the class)."""
        if self.interrupt is not None:
            exc, self.interrupt = self.interrupt, None
            raise exc

    def image(self) -> bytes:
        """The whole file as HDF5 wrote it."""
        if self.memory is not None:
            return bytes(self.memory[:self.size])
        return self._read(0, self.size)

    def give_back_reserve(self) -> None:
        """Cut the file to HDF5's end of file (the allocated reserve beyond it is freed)."""
        with contextlib.suppress(OSError):
            os.ftruncate(self.fd, self.size)

    def close(self) -> None:
        """Close the descriptor (once: :attr:`fd` is ``-1`` after)."""
        fd, self.fd = self.fd, -1
        if fd >= 0:
            with contextlib.suppress(OSError):
                os.close(fd)

    def _completed(self, fn: Any, *args: Any) -> Any:
        for _ in range(100):
            try:
                return fn(*args)
            except (KeyboardInterrupt, SystemExit) as exc:  # from a signal handler
                self.interrupt = self.interrupt or exc
        return fn(*args)

    def _read(self, pos: int, n: int) -> bytes:
        if self.memory is not None:
            data = bytes(self.memory[pos:pos + n])
        else:
            data = b""
            while len(data) < n:
                more = _pread(self.fd, n - len(data), pos + len(data))
                if not more:
                    break
                data += more
        return data.ljust(n, b"\0")

    def _read_back(self, pos: int, n: int) -> bytes:
        """What HDF5 reads: a read the disk refuses (EIO) is a failed write's path (memory
        from then on, :attr:`problem`), never an error inside HDF5."""
        try:
            return self._read(pos, n)
        except OSError as exc:
            self._to_memory(exc)
            return self._read(pos, n)

    def _write(self, pos: int, data: bytes | bytearray | memoryview) -> None:
        end = pos + len(data)
        if self.memory is None:
            self.allocate(end)
            try:
                write_all(self.fd, data, at=pos)
                self.disk_size = max(self.disk_size, end)
                return
            except OSError as exc:
                self._to_memory(exc)
        mem = self.memory
        if len(mem) < pos:
            mem.extend(bytes(pos - len(mem)))
        mem[pos:end] = data

    def _resize(self, size: int) -> None:
        if self.memory is not None:
            if size < len(self.memory):
                del self.memory[size:]
            else:
                self.memory.extend(bytes(size - len(self.memory)))
            return
        if size <= self.disk_size:  # shorter: the reserve stays allocated until close
            return
        try:
            os.ftruncate(self.fd, size)
            self.disk_size = size
        except OSError as exc:
            self._to_memory(exc)
            self._resize(size)

    def allocate(self, end: int) -> None:
        """Keep :attr:`reserve` bytes allocated beyond ``end``."""
        if not self.reserve or end + self.reserve <= self.disk_size:
            return
        want = end + 2 * self.reserve
        try:
            _fallocate(self.fd, self.disk_size, want - self.disk_size)
        except OSError as exc:
            self.reserve = 0  # writing goes on into what there is
            if exc.errno in _FULL:
                if self.problem is None:
                    self.problem, self.refused = exc, want - self.disk_size
            else:  # a file system without allocation (EOPNOTSUPP): no reserve there
                log.debug("no space reserved: %s", exc)
            return
        self.disk_size = want

    def _to_memory(self, exc: OSError) -> None:
        log.debug("writing failed (%s); the session continues in memory", exc)
        self.problem = self.problem or exc
        self.failed = exc
        image, step = bytearray(self.size), 1 << 16
        for pos in range(0, self.size, step):  # what cannot be read back: zeros
            with contextlib.suppress(OSError):
                part = self._read(pos, min(step, self.size - pos))
                image[pos:pos + len(part)] = part
        self.memory = image
