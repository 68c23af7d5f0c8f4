"""Session files: one HDF5 file per flight, written crash-safe, read back as numpy arrays.

The format (``docs/session-format.md``) is the contract between the flight runner, replay,
importers and ``sysid``. :class:`SessionWriter` is the only writer and :func:`open_session` the
only reader.

Crash safety: the writer uses HDF5 SWMR (single writer, multiple readers). All groups and
attributes exist before SWMR starts; rows are buffered in memory and appended at most
``flush_interval`` (1 s) apart, and the file is ``fsync``-ed every ``fsync_interval`` seconds (on a
background thread: a slow card never delays the caller, the flight runner), so a
process killed at any instant leaves a readable file that lacks at most about one second.
A row resized but not yet written reads as NaN ``host_time`` and is dropped by the reader.

Failures (``docs/session-format.md``, "When the disk fills"): HDF5 writes through
:class:`_SessionFile`, so a write the disk refuses never reaches HDF5 (h5py cannot close a file
whose writes keep failing). A flight's writer keeps :data:`RESERVE_BYTES` allocated ahead and
says so (:attr:`SessionWriter.trouble`) when the disk, a quota or the file size limit will not
give more, while the landing still fits; a write that fails all the same goes on in memory and is
saved at close if there is room then. At close the writer checks that its path still names the
file it wrote (a folder moved or deleted meanwhile) and reports where the session really is.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import logging
import math
import os
import stat
import tempfile
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from cfsession import __version__
from cfsession.errors import SessionError
from cfsession.schema import (
    SCHEMA_NAME,
    SCHEMA_VERSION,
    TEXT_BYTES,
    StreamSpec,
    events_spec,
    link_spec,
    phases_spec,
    setpoints_spec,
)

__all__ = ["RESERVE_BYTES", "SessionWriter", "check_room", "check_writable", "event_rows",
           "standard_streams"]

log = logging.getLogger(__name__)

_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0)
_LEVELS = {"debug": 1, "info": 2, "warning": 3, "error": 4, "critical": 5}


def standard_streams() -> list[StreamSpec]:
    """The streams every flight session has besides its log blocks."""
    return [setpoints_spec(), events_spec(), phases_spec(), link_spec()]


def _attr_value(value: Any) -> Any:
    """HDF5-storable form of a metadata value (dicts and lists become JSON text)."""
    if value is None:
        return ""
    if isinstance(value, Mapping | list | tuple):
        return json.dumps(value, sort_keys=True, default=str)
    return value


def event_rows(*, t: float, text: str, level: str = "info", source: str = "runner") -> list[tuple]:
    """Rows of the ``events`` stream for one event: text longer than one row continues."""
    data = text.encode("utf-8", errors="replace")
    lvl, src = _LEVELS.get(level, 2), source.encode()[:16]
    pieces = [data[i : i + TEXT_BYTES] for i in range(0, len(data), TEXT_BYTES)] or [b""]
    return [(t, lvl, src, piece, int(i > 0)) for i, piece in enumerate(pieces)]


RESERVE_BYTES = 256 << 10
"""Disk space a flight's session keeps allocated beyond what it has written (``reserve`` of
:class:`SessionWriter`, used by the flight recorder): once the disk, a quota or the file size
limit (``ulimit -f``) will not give more, :attr:`SessionWriter.trouble` says so while this much
room is still there for the landing (a few seconds need about 10 KiB a second)."""

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


def _problem(exc: OSError, folder: Path) -> str:
    """One line for a write (or an allocation) in ``folder`` that the disk refused."""
    if exc.errno == errno.EFBIG:
        limit = _fsize_limit()
        if limit is not None:
            return (f"file size limit reached writing in {folder}: a file may not grow past "
                    f"{limit} bytes (ulimit -f)")
        return f"file too large for the file system of {folder}"
    if exc.errno in _FULL:
        return f"{_FULL[exc.errno]}: no room left in {folder} ({exc.strerror or exc})"
    return f"cannot write in {folder} ({exc.strerror or exc})"


def check_room(path: str | os.PathLike[str], nbytes: int = 2 * RESERVE_BYTES) -> None:
    """Allocate ``nbytes`` in the existing, empty file ``path`` (a probe: its caller removes
    it) or say in one line (:class:`SessionError`) that the disk, a quota or the file size
    limit will not give them."""
    fd = os.open(path, os.O_WRONLY | _NOFOLLOW)
    try:
        _fallocate(fd, 0, nbytes)
    except OSError as exc:
        if exc.errno in _FULL:
            raise SessionError(f"{_problem(exc, Path(path).parent)}; a flight's session needs "
                               f"{nbytes >> 10} KiB to start") from None
        log.debug("cannot allocate in %s: %s", path, exc)  # no allocation on this file system
    finally:
        os.close(fd)


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


def _fallocate(fd: int, offset: int, length: int) -> None:
    if not hasattr(os, "posix_fallocate"):  # macOS, Windows: no reserve
        raise OSError(errno.EOPNOTSUPP, "posix_fallocate is not available")
    os.posix_fallocate(fd, offset, length)


class _SessionFile:
    """What HDF5 writes a session through (h5py's ``fileobj`` driver): positioned reads and
    writes on one descriptor, so that no failing write ever reaches HDF5 (h5py cannot close a
    file whose writes keep failing: it retried for ever at exit and crashed the interpreter).

    * ``reserve`` bytes beyond the end written are kept allocated (``posix_fallocate``, a
      reserve's worth at a time). When the disk, a quota or the file size limit refuses more,
      :attr:`problem` is set and writing goes on into what is allocated.
    * A write that fails all the same (another process took the space, an I/O error) sets
      :attr:`problem` and :attr:`failed`; the file's bytes are read into memory and everything
      from then on (that write included) goes to :attr:`memory`, so HDF5 finishes the file
      there and :class:`SessionWriter` can save it whole at close if there is room again.
    * Past the end reads as zeros, as HDF5's own drivers read it.
    * A signal handler that raises (Ctrl-C) while HDF5 is inside one of these calls does not
      interrupt it: the call completes (each is idempotent) and :meth:`raise_interrupt`
      raises the exception once HDF5 has returned.
    """

    def __init__(self, fd: int, *, reserve: int = 0) -> None:
        self.fd, self.reserve = fd, reserve
        self.pos = 0
        self.size = 0  # HDF5's end of file
        self.disk_size = 0  # bytes the descriptor's file has (written or allocated)
        self.memory: bytearray | None = None
        self.problem: OSError | None = None  # the first refusal (allocation or write)
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
        data = self._completed(self._read, self.pos, n)
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

    def _write(self, pos: int, data: bytes | bytearray | memoryview) -> None:
        end = pos + len(data)
        if self.memory is None:
            self._allocate(end)
            view, done = memoryview(data).cast("B"), 0
            try:
                while done < len(view):
                    n = _pwrite(self.fd, view[done:], pos + done)
                    if n <= 0:
                        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
                    done += n
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

    def _allocate(self, end: int) -> None:
        """Keep :attr:`reserve` bytes allocated beyond ``end``."""
        if not self.reserve or end + self.reserve <= self.disk_size:
            return
        want = end + 2 * self.reserve
        try:
            _fallocate(self.fd, self.disk_size, want - self.disk_size)
        except OSError as exc:
            self.reserve = 0  # writing goes on into what there is
            if exc.errno in _FULL:
                self.problem = self.problem or exc
            else:  # a file system without allocation (EOPNOTSUPP): no reserve there
                log.debug("no space reserved: %s", exc)
            return
        self.disk_size = want

    def _to_memory(self, exc: OSError) -> None:
        log.debug("write failed (%s); the session continues in memory", exc)
        self.problem = self.problem or exc
        self.failed = exc
        try:
            image = bytearray(self._read(0, self.size))
        except OSError:  # unreadable too: what HDF5 reads back of it is zeros
            image = bytearray(self.size)
        self.memory = image


class SessionWriter:
    """Writes one flight to ``path``; crash-safe, for one thread.

    Parameters
    ----------
    path: the ``.h5`` file to create (its folder is created; an existing file is refused).
    streams: every stream the flight will write (log blocks plus :func:`standard_streams`);
        SWMR allows no new datasets once writing has started.
    metadata: root attributes: ``uri``, ``firmware``, ``protocol_version``, ``plan_name``,
        ``plan_text``, ``params`` (dict), ``phase_table`` (list), ...; dicts/lists become JSON.
    start_time_ns: wall-clock start (ns since the Unix epoch); defaults to now.
    flush_interval, fsync_interval: seconds (wall clock) between flushes / ``fsync`` calls.
    compress_on_close: on a clean close, rewrite the file with gzip-compressed chunks.
    reserve: bytes kept allocated beyond the end written (:data:`RESERVE_BYTES` for a flight):
        a disk that cannot give them is :attr:`trouble` while they are still there. A file
        that cannot get them at creation is refused (:class:`SessionError`, nothing left).

    A disk that fills, a file size limit, a file moved or deleted while written: see
    :attr:`trouble`, :meth:`close`, :attr:`notes` and :attr:`saved_until`.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        streams: Sequence[StreamSpec],
        metadata: Mapping[str, Any] | None = None,
        start_time_ns: int | None = None,
        flush_interval: float = 1.0,
        fsync_interval: float = 3.0,
        compress_on_close: bool = True,
        reserve: int = 0,
    ) -> None:
        self.path = Path(path)
        if self.path.is_symlink():
            raise SessionError(f"{self.path}: is a symbolic link; refusing to write through it")
        if self.path.exists():
            raise SessionError(f"{self.path}: already exists; choose another output path")
        names = [s.name for s in streams]
        if len(set(names)) != len(names):
            raise ValueError(f"stream names must be unique, got {names}")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._specs = {s.name: s for s in streams}
        self._buffers: dict[str, list[tuple]] = {s.name: [] for s in streams}
        self._counts = dict.fromkeys(self._specs, 0)
        self.flush_interval = flush_interval
        self.fsync_interval = fsync_interval
        self.compress_on_close = compress_on_close
        self.start_time_ns = time.time_ns() if start_time_ns is None else start_time_ns
        self.notes: list[str] = []
        self.saved_until: float | None = None
        self.closed = False
        self._sync_error: OSError | None = None
        self._fsync_thread: threading.Thread | None = None
        self._newest = -math.inf  # host_time of the newest row flushed before any failure
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | _NOFOLLOW, 0o666)
        except FileExistsError:
            raise SessionError(f"{self.path}: already exists; choose another output path"
                               ) from None
        self._io = _SessionFile(fd, reserve=reserve)
        self._datasets: dict[str, h5py.Dataset] = {}
        try:
            self._io._allocate(0)
            self._file = h5py.File(self._io, "w", libver="latest")
            self._write_header(dict(metadata or {}))
            for spec in streams:
                self._create_stream(spec)
            self._file.swmr_mode = True
            self._file.flush()
            if self.trouble:
                need = f"; a flight's session needs {2 * reserve >> 10} KiB to start" \
                    if reserve else ""
                raise SessionError(f"{self.trouble}{need}")
        except BaseException:
            self._abandon()
            raise
        self._io.raise_interrupt()
        self._last_flush = self._last_fsync = time.monotonic()
        log.info("recording session to %s", self.path)

    def _abandon(self) -> None:
        """Close and remove a file that could not be set up."""
        with contextlib.suppress(Exception):
            if getattr(self, "_file", None) is not None:
                self._file.close()
        self.closed = True
        with contextlib.suppress(OSError):
            os.close(self._io.fd)
        with contextlib.suppress(OSError):
            self.path.unlink()

    @property
    def trouble(self) -> str:
        """One line once the disk (a quota, the file size limit) refused this file room, or a
        write or ``fsync`` failed; ``""`` until then. With a ``reserve`` the rows still reach
        the file (the reserve's room); after a failed write they are kept in memory and saved
        at close if there is room then (:meth:`close`). Whoever flies should land now."""
        exc = self._io.problem or self._sync_error
        return "" if exc is None else _problem(exc, self.path.parent)

    @property
    def disk_full(self) -> bool:
        """Whether the disk or a quota refused room (not merely the file size limit)."""
        exc = self._io.problem
        return exc is not None and exc.errno in (errno.ENOSPC, errno.EDQUOT)

    # ----------------------------------------------------------------- layout
    def _write_header(self, metadata: dict[str, Any]) -> None:
        a = self._file.attrs
        a["schema"] = SCHEMA_NAME
        a["schema_version"] = SCHEMA_VERSION
        a["start_time_ns"] = np.int64(self.start_time_ns)
        start = time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(self.start_time_ns / 1e9))
        a["start_time_iso"] = f"{start}.{self.start_time_ns % 10**9 // 10**6:03d}Z"
        a["software_version"] = f"groundstation {__version__}"
        for key, value in metadata.items():
            a[key] = _attr_value(value)
        # Attributes updated in place at close: they must exist (same size) before SWMR.
        a["closed_cleanly"] = np.int8(0)
        a["duration_s"] = np.float64(np.nan)
        a["summary"] = " " * 4096

    def _create_stream(self, spec: StreamSpec) -> None:
        group = self._file.create_group(spec.name)
        group.attrs["kind"] = spec.kind
        group.attrs["description"] = spec.description
        if spec.period_s is not None:
            group.attrs["period_s"] = spec.period_s
        for key, value in spec.attrs.items():
            group.attrs[key] = value
        row_bytes = spec.dtype.itemsize
        rows_per_s = 1.0 / spec.period_s if spec.period_s else 50.0
        chunk = int(min(max(rows_per_s, 16), max(16, 65536 // row_bytes)))  # about 1 s
        ds = group.create_dataset(
            "data",
            shape=(0,),
            maxshape=(None,),
            dtype=spec.dtype,
            chunks=(chunk,),
            fillvalue=spec.fill_row(),
        )
        ds.attrs["fields"] = [f.name for f in spec.fields]
        ds.attrs["units"] = [f.unit for f in spec.fields]
        ds.attrs["sources"] = [f.source for f in spec.fields]
        self._datasets[spec.name] = ds

    # ---------------------------------------------------------------- writing
    @property
    def streams(self) -> list[str]:
        return list(self._specs)

    def append(self, stream: str, row: tuple) -> None:
        """Queue one row (a tuple in the stream's field order) and flush if it is time."""
        try:
            self._buffers[stream].append(row)
        except KeyError:
            raise KeyError(f"no stream {stream!r} in this session; have {self.streams}") from None
        self.maybe_flush()

    def extend(self, stream: str, rows: Iterable[tuple]) -> None:
        """Queue many rows at once."""
        self._buffers[stream].extend(rows)
        self.maybe_flush()

    def event(self, *, t: float, text: str, level: str = "info", source: str = "runner") -> None:
        """Record an event; text longer than one row continues on following rows."""
        self.extend("events", event_rows(t=t, text=text, level=level, source=source))

    def phase(self, *, t: float, phase_id: int, name: str, kind: str) -> None:
        """Mark the start of a phase (it lasts until the next phase row)."""
        self.append("phases", (t, phase_id, name.encode()[:32], kind.encode()[:16]))

    def maybe_flush(self) -> None:
        """Flush if ``flush_interval`` has passed since the last flush (call it when idle too)."""
        if time.monotonic() - self._last_flush >= self.flush_interval:
            self.flush()

    def flush(self, *, fsync: bool | None = None) -> None:
        """Append buffered rows to the file and make them visible to readers."""
        self._flush(fsync=fsync)
        self._io.raise_interrupt()

    def _flush(self, *, fsync: bool | None) -> None:
        if self.closed:
            return
        on_disk = self._io.failed is None
        newest = -math.inf
        for name, rows in self._buffers.items():
            if not rows:
                continue
            ds = self._datasets[name]
            block = np.array(rows, dtype=ds.dtype)
            n0 = ds.shape[0]
            ds.resize((n0 + len(block),))
            ds[n0:] = block
            self._counts[name] += len(block)
            rows.clear()
            with contextlib.suppress(ValueError, TypeError):  # host_time is the first field
                newest = max(newest, float(np.nanmax(block[block.dtype.names[0]])))
        self._file.flush()
        if on_disk and self._io.failed is None:
            self._newest = max(self._newest, newest)
        now = time.monotonic()
        self._last_flush = now
        if self._io.memory is None:
            if fsync:
                self._join_fsync()
                self._sync()
                self._last_fsync = now
            elif fsync is None and now - self._last_fsync >= self.fsync_interval:
                self._fsync_in_background()
                self._last_fsync = now

    def _sync(self) -> None:
        """``fsync``; a failure (the disk, an I/O error) is :attr:`trouble`, never raised."""
        try:
            os.fsync(self._io.fd)
        except OSError as exc:
            self._sync_error = self._sync_error or exc

    def _fsync_in_background(self) -> None:
        """``fsync`` off the caller's thread: on a slow card it can take longer than a setpoint
        period, and the caller is the flight runner. One at a time; joined before closing."""
        if self._fsync_thread is not None and self._fsync_thread.is_alive():
            return  # the previous one is still syncing: it covers these rows too, or the next
        self._fsync_thread = threading.Thread(target=self._sync, name="session-fsync",
                                              daemon=True)
        self._fsync_thread.start()

    def _join_fsync(self) -> None:
        if self._fsync_thread is not None:
            self._fsync_thread.join()
            self._fsync_thread = None

    def counts(self) -> dict[str, int]:
        """Rows per stream, written plus buffered."""
        return {k: self._counts[k] + len(self._buffers[k]) for k in self._specs}

    # ---------------------------------------------------------------- closing
    def close(self, *, duration_s: float | None = None, summary: Mapping | None = None) -> Path:
        """Flush everything, mark the file closed cleanly, optionally compress; returns the
        path the session is at.

        Before that it checks that :attr:`path` still names the file written (a folder moved
        or deleted while the file was open: on POSIX the open file lives on). Moved: the
        session's new name is returned. Deleted (or moved where its name cannot be found):
        it is written again, from the open file, to :attr:`path` (the folder created again;
        ``-2`` ... if the name is taken meanwhile). After a failed write (:attr:`trouble`) the
        whole file, kept in memory, is saved compressed if there is room now. Each of these is
        one line in :attr:`notes` (and a logged warning). If there is no room, the file keeps
        what reached it, rows up to :attr:`saved_until` (``host_time``), and ``close`` raises a
        one-line :class:`SessionError` saying so (:attr:`path` names the file); so it does
        when the session cannot be saved anywhere (:attr:`saved_until` stays ``None``)."""
        if self.closed:
            return self.path
        try:
            try:
                self._flush(fsync=False)
                a = self._file.attrs
                a["closed_cleanly"] = np.int8(1)
                if duration_s is not None:
                    a["duration_s"] = np.float64(duration_s)
                text = json.dumps(dict(summary or {}), sort_keys=True, default=str)
                a["summary"] = text[:4096].ljust(4096)
                self._file.flush()
            finally:
                self.closed = True
                with contextlib.suppress(Exception):
                    self._file.close()
                self._join_fsync()
            self.path = self._settle()
        finally:
            with contextlib.suppress(OSError):
                os.close(self._io.fd)
            for note in self.notes:
                log.warning("%s", note)
        self._io.raise_interrupt()
        log.info("session closed: %s", self.path)
        return self.path

    def _settle(self) -> Path:
        """Where the closed session ends up (see :meth:`close`); the descriptor is still open."""
        sink, original = self._io, self.path
        trouble = self.trouble
        if sink.memory is None:
            with contextlib.suppress(OSError):
                os.ftruncate(sink.fd, sink.size)  # the reserve is given back
            self._sync()
        current, gone = self._whereabouts()
        if current is not None and current != original:
            self.notes.append(f"{original} was moved while being written; the session is now "
                              f"{current}")
        if sink.memory is not None:  # a write failed: the whole file is in memory
            return self._save_from_memory(current or original, trouble=trouble, gone=gone)
        if current is None:  # the open file still holds it
            return self._write_again(original, sink.image(), gone=gone,
                                     source="the still open file")
        if self.compress_on_close and not self.disk_full:
            try:
                _repack(current)
            except Exception as exc:  # the uncompressed file is complete: never lose it
                log.debug("compressing %s", current, exc_info=True)
                log.warning("could not compress %s (%s); kept uncompressed", current,
                            _one_line(exc))
        elif self.compress_on_close:
            log.info("%s not compressed: the disk is full", current)
        return current

    def _whereabouts(self) -> tuple[Path | None, str]:
        """The name of the open file: :attr:`path`, or its new name when it (or its folder) was
        moved (from ``/proc/self/fd``); ``None`` and how it went when it has none to be
        found."""
        fd = self._io.fd
        st = os.fstat(fd)
        if st.st_nlink == 0:
            return None, "was deleted while being written (its folder removed?)"

        def ours(p: Path) -> bool:
            try:
                cur = os.lstat(p)
            except (OSError, ValueError):
                return False
            return (cur.st_dev, cur.st_ino) == (st.st_dev, st.st_ino)

        unknown = "was moved while being written, to a place unknown"
        if ours(self.path):
            return self.path, ""
        try:
            name = Path(os.readlink(f"/proc/self/fd/{fd}"))
        except OSError:  # no /proc (not Linux)
            return None, unknown
        return (name, "") if ours(name) else (None, unknown)

    def _write_again(self, original: Path, image: bytes, *, gone: str, source: str) -> Path:
        """``image`` (the closed file's bytes) to a new file at ``original`` (its folder made
        again, ``-2`` ... if taken); one-line :class:`SessionError` if that fails."""
        try:
            target = _save_image(image, original, compress=self.compress_on_close,
                                 mode=_mode_of(self._io.fd))
        except Exception as exc:
            log.debug("writing %s again", original, exc_info=True)
            raise SessionError(f"{original} {gone}, and writing it again failed "
                               f"({_one_line(exc)}): the session is lost") from None
        self.notes.append(f"{original} {gone}; the session was written again, from {source}, "
                          f"to {target}")
        return target

    def _save_from_memory(self, target: Path, *, trouble: str, gone: str) -> Path:
        """After a failed write: the whole session from memory, compressed, to ``target``
        (replacing what reached the disk there, or a new file if it is gone)."""
        image, mode = self._io.image(), _mode_of(self._io.fd)
        try:
            if gone:
                return self._write_again(target, image, gone=gone, source="memory")
            saved = _save_image(image, target, compress=True, mode=mode, replace=True)
        except SessionError:
            raise
        except Exception as exc:
            log.debug("saving %s from memory", target, exc_info=True)
            if self._newest == -math.inf:
                raise SessionError(f"{trouble}; no row reached {target} (it holds the metadata "
                                   f"only) and saving the session at close failed too "
                                   f"({_one_line(exc)}): its data are lost") from None
            self.saved_until, self.path = self._newest, target
            raise SessionError(f"{target} holds the session up to "
                               f"{math.floor(self._newest * 10) / 10:.1f} s only "
                               f"({trouble}; saving the rest at close failed: "
                               f"{_one_line(exc)})") from None
        self.notes.append(f"{trouble}; the whole session, kept in memory since, was saved "
                          f"(compressed) to {saved} at close")
        return saved

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _one_line(exc: BaseException) -> str:
    """An exception as one short line (HDF5's messages span lines)."""
    text = " ".join(str(exc).split()) if str(exc).strip() else type(exc).__name__
    if isinstance(exc, OSError) and exc.strerror:
        text = exc.strerror
    return text[:200]


def _mode_of(fd: int) -> int:
    """Permission bits of the open file (the umask's, from its creation)."""
    try:
        return stat.S_IMODE(os.fstat(fd).st_mode) & 0o777
    except OSError:
        return 0o644


def _claim_new(path: Path) -> Path:
    """Create an empty file exclusively at ``path`` or the first free ``stem-N`` name."""
    path.parent.mkdir(parents=True, exist_ok=True)
    for n in range(1, 1001):
        candidate = path if n == 1 else path.with_name(f"{path.stem}-{n}{path.suffix}")
        try:
            os.close(os.open(candidate, os.O_CREAT | os.O_EXCL | os.O_WRONLY | _NOFOLLOW, 0o600))
        except FileExistsError:
            continue
        return candidate
    raise FileExistsError(errno.EEXIST, f"{path} and 999 other names taken")


def _save_image(image: bytes, target: Path, *, compress: bool, mode: int,
                replace: bool = False) -> Path:
    """A closed session's bytes to ``target``: compressed (:func:`_copy_compressed`) or as they
    are, through a temporary file renamed onto ``target`` (over it with ``replace``, else onto a
    name claimed exclusively). Returns the name written."""
    if not replace:
        target = _claim_new(target)
    try:
        if compress:
            with h5py.File(io.BytesIO(image), "r") as src:
                tmp = _write_compressed(src, target, mode=mode)
        else:
            tmp = _write_tmp(target, mode=mode, fill=lambda fd: _write_all(fd, image))
        os.replace(tmp, target)
    except BaseException:
        if not replace:
            with contextlib.suppress(OSError):
                target.unlink()
        raise
    return target


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _write_tmp(path: Path, *, mode: int, fill: Any) -> Path:
    """A file created exclusively (``O_EXCL``, random name) beside ``path``, ``fill(fd)``-ed,
    ``fsync``-ed, with ``mode``; removed again if anything fails."""
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".repack")
    tmp = Path(tmp_name)
    try:
        try:
            os.fchmod(fd, mode)
            fill(fd)
            os.fsync(fd)
        finally:
            os.close(fd)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return tmp


def _write_compressed(src: h5py.File, path: Path, *, mode: int) -> Path:
    """``src`` compressed into a new temporary file beside ``path`` (:func:`_write_tmp`),
    through :class:`_SessionFile`: a disk that fills is an :class:`OSError`, never a failing
    HDF5 file."""

    def fill(fd: int) -> None:
        sink = _SessionFile(fd)
        with h5py.File(sink, "w", libver="latest") as dst:
            _copy_compressed(src, dst)
        sink.raise_interrupt()
        if sink.failed is not None:
            raise sink.failed

    return _write_tmp(path, mode=mode, fill=fill)


def _repack(path: Path) -> None:
    """Rewrite ``path`` with gzip-compressed chunks, atomically: into a file created exclusively
    (``O_EXCL``, random name) in the same folder and written through that descriptor, so no
    name planted beforehand (a symlink) is ever followed; then renamed over ``path``, unless
    ``path`` has become a symlink meanwhile. The rewrite keeps ``path``'s permission bits (the
    umask's, from when it was created): ``mkstemp`` makes its file owner-only."""
    st = os.lstat(path)
    mode = stat.S_IMODE(st.st_mode) & 0o777 if stat.S_ISREG(st.st_mode) else 0o600
    with h5py.File(path, "r") as src:
        tmp = _write_compressed(src, path, mode=mode)
    try:
        if path.is_symlink():
            raise SessionError(f"{path}: became a symbolic link while closing; left as it is "
                               f"(the data are in {tmp})")
        os.replace(tmp, path)
    except BaseException:
        if tmp.exists() and not path.is_symlink():
            tmp.unlink()
        raise


def _copy_compressed(src: h5py.File, dst: h5py.File) -> None:
    """Every stream of ``src`` into ``dst`` with gzip-compressed chunks, attributes kept."""
    for key, value in src.attrs.items():
        dst.attrs[key] = value
    if isinstance(value := src.attrs.get("summary"), str):
        dst.attrs["summary"] = value.rstrip()
    for name, group in src.items():
        out = dst.create_group(name)
        for key, value in group.attrs.items():
            out.attrs[key] = value
        data = group["data"]
        ds = out.create_dataset(
            "data",
            data=data[()],
            maxshape=(None,),
            chunks=data.chunks,
            compression="gzip",
            compression_opts=4,
            shuffle=True,
            fillvalue=data.fillvalue,
        )
        for key, value in data.attrs.items():
            ds.attrs[key] = value


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
