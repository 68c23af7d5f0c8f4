"""The one writer of session files: :class:`SessionWriter`, and the public functions around it.

The format (``docs/session-format.md``) is the contract between the flight runner, replay,
importers and ``sysid``. :class:`SessionWriter` is the only writer and
:func:`cfsession.open_session` the only reader.

Crash safety: the writer uses HDF5 SWMR (single writer, multiple readers). All groups and
attributes exist before SWMR starts; rows are buffered in memory and appended at most
``flush_interval`` (1 s) apart, and the file is ``fsync``-ed every ``fsync_interval`` seconds (on a
background thread: a slow card never delays the caller, the flight runner), so a
process killed at any instant leaves a readable file that lacks at most about one second.
A row resized but not yet written reads as NaN ``host_time`` and is dropped by the reader.

Failures (``docs/session-format.md``, "When the disk fills"): HDF5 writes through
:class:`cfsession.diskfile.SessionFile`, so a write the disk refuses never reaches HDF5. A
flight's writer keeps :data:`RESERVE_BYTES` allocated ahead and says so
(:attr:`SessionWriter.trouble`) when the disk, a quota or the file size limit will not give
more, while the landing still fits; a write that fails all the same goes on in memory and is
saved at close if there is room then. At close :class:`cfsession.saving.Settlement` checks that
the writer's path still names the file it wrote (a folder moved or deleted meanwhile) and puts
the session where it belongs.
"""

from __future__ import annotations

import contextlib
import errno
import json
import logging
import math
import os
import threading
import time
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

import h5py
import numpy as np

from cfsession import __version__
from cfsession.diskfile import (
    OPEN_FLAGS,
    RESERVE_BYTES,
    SessionFile,
    check_room,
    check_writable,
    disk_problem,
)
from cfsession.errors import SessionError
from cfsession.saving import Settlement
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

#: Size of the ``summary`` attribute: made before SWMR, rewritten in place at close.
SUMMARY_CHARS = 4096


def summary_json(summary: Mapping, *, limit: int = SUMMARY_CHARS,
                 keep: Sequence[str] = ("aborted", "cause")) -> str:
    """``summary`` as strict JSON (NaN and infinities as ``null``) in at most ``limit``
    characters: long strings are shortened first (a disk-full cause naming a long path), then
    the largest entries other than ``keep`` are left out, counted under ``"truncated"``.
    Cutting the text at ``limit`` broke the JSON, and ``info`` then showed no summary at all."""
    text = json.dumps(_shortened(summary, None), sort_keys=True, default=str, allow_nan=False)
    for cut in (512, 160, 60):
        if len(text) <= limit:
            return text
        short = _shortened(summary, cut)
        text = json.dumps(short, sort_keys=True, default=str, allow_nan=False)
    sizes = {k: len(json.dumps({k: v}, default=str)) for k, v in short.items() if k not in keep}
    largest = sorted(sizes, key=sizes.__getitem__, reverse=True)
    excess, n_out = len(text) - limit + 40, 0  # 40: room for the "truncated" entry
    while n_out < len(largest) and (excess > 0 or len(text) > limit):
        excess -= sizes[largest[n_out]]
        n_out += 1
        if excess <= 0:  # by the estimate it fits: measure
            left = {k: v for k, v in short.items() if k not in largest[:n_out]}
            text = json.dumps({**left, "truncated": f"{n_out} entries left out"},
                              sort_keys=True, default=str, allow_nan=False)
    return text if len(text) <= limit else "{}"  # the kept entries alone are short


def _shortened(value: Any, keep: int | None) -> Any:
    """``value`` with strings over ``keep`` characters cut (None: kept whole), keys as
    strings, and non-finite floats as None (strict JSON)."""
    if isinstance(value, str):
        return f"{value[:keep]}..." if keep is not None and len(value) > keep else value
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if np.isfinite(value) else None
    if isinstance(value, Mapping):
        return {_shortened(str(k), keep): _shortened(v, keep) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_shortened(v, keep) for v in value]
    return value


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
        self._bad_rows: dict[str, int] = {}  # rows left out per stream (:meth:`_block`)
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL | OPEN_FLAGS,
                         0o666)
        except FileExistsError:
            raise SessionError(f"{self.path}: already exists; choose another output path"
                               ) from None
        self._io = SessionFile(fd, reserve=reserve)
        self._datasets: dict[str, h5py.Dataset] = {}
        try:
            self._io.allocate(0)
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
            self._io.raise_interrupt()  # a Ctrl-C inside HDF5: the file is abandoned too
        except BaseException:
            self._abandon()
            raise
        self._last_flush = self._last_fsync = time.monotonic()
        log.info("recording session to %s", self.path)

    def _abandon(self) -> None:
        """Close and remove a file that could not be set up."""
        with contextlib.suppress(Exception):
            if getattr(self, "_file", None) is not None:
                self._file.close()
        self.closed = True
        self._io.close()
        with contextlib.suppress(OSError):
            self.path.unlink()

    @property
    def trouble(self) -> str:
        """One line once the disk (a quota, the file size limit) refused this file room, or a
        write or ``fsync`` failed; ``""`` until then. With a ``reserve`` the rows still reach
        the file (the reserve's room); after a failed write they are kept in memory and saved
        at close if there is room then (:meth:`close`). Whoever flies should land now."""
        exc = self._io.problem or self._sync_error
        if exc is None:
            return ""
        wanted = self._io.refused if exc is self._io.problem else 0
        return disk_problem(exc, self.path.parent, wanted=wanted)

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
        a["summary"] = " " * SUMMARY_CHARS

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
            block = self._block(name, rows, ds.dtype)
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

    def _block(self, name: str, rows: list[tuple], dtype: np.dtype) -> np.ndarray:
        """``rows`` as one structured array; a row that does not fit the stream's fields (its
        length, a value that is no number) is left out, with a note, instead of costing the
        rows buffered with it (and at close, the clean close)."""
        if all(isinstance(row, tuple) for row in rows):  # a list or scalar spreads into fields
            try:
                return np.array(rows, dtype=dtype)
            except (ValueError, TypeError, OverflowError):
                pass
        good, bad = [], 0
        for row in rows:
            try:
                item = np.array(tuple(row), dtype=dtype)  # a scalar or a list is no row
                if item.ndim:
                    raise ValueError("not one row")
                good.append(item)
            except (ValueError, TypeError, OverflowError):
                bad += 1
        if bad:
            self._bad_rows[name] = self._bad_rows.get(name, 0) + bad
            log.warning("%s: %d row(s) of stream %r did not fit its fields and were left out",
                        self.path.name, bad, name)
        return np.array(good, dtype=dtype)

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
        ``-2`` ... if taken), else where it can (:func:`~cfsession.saving.fallbacks`). After a
        failed write (:attr:`trouble`) the whole file, kept in memory, is saved compressed if
        there is room (over the partial file if none beside it). Each is a line in :attr:`notes`
        (and a logged warning). If there is no room, the file keeps what reached it, rows up to
        :attr:`saved_until` (``host_time``), and ``close`` raises a one-line
        :class:`SessionError` saying so (:attr:`path` names the file); so it does
        when the session cannot be saved anywhere (:attr:`saved_until` stays ``None``)."""
        if self.closed:
            return self.path
        try:
            try:
                self._flush(fsync=False)
                for name, bad in self._bad_rows.items():  # in the notes, and the file's events
                    note = f"{bad} row(s) of stream {name!r} did not fit its fields and were " \
                        "left out"
                    self.notes.append(note)
                    if "events" in self._specs and self._specs["events"].kind == "events":
                        self.event(t=self._newest if math.isfinite(self._newest) else 0.0,
                                   text=note, level="error", source="recorder")
                if self._bad_rows:  # those events
                    self._flush(fsync=False)
                a = self._file.attrs
                a["closed_cleanly"] = np.int8(1)
                if duration_s is not None:
                    a["duration_s"] = np.float64(duration_s)
                stored = dict(summary or {})
                if "file" in stored:  # its name only (a folder may move): docs/session-format.md
                    stored["file"] = self.path.name
                a["summary"] = summary_json(stored).ljust(SUMMARY_CHARS)
                self._file.flush()
            finally:
                self.closed = True
                with contextlib.suppress(Exception):
                    self._file.close()
                self._join_fsync()
            self.path = self._settle()
        finally:
            self._io.close()
            for note in self.notes:
                log.warning("%s", note)
        self._io.raise_interrupt()
        log.info("session closed: %s", self.path)
        return self.path

    def _settle(self) -> Path:
        """Where the closed session ends up (see :meth:`close`); the descriptor is still open."""
        trouble = self.trouble
        if self._io.memory is None:
            self._io.give_back_reserve()
            self._sync()
        settlement = Settlement(self._io, self.path, compress=self.compress_on_close,
                                newest=self._newest, notes=self.notes)
        try:
            return settlement.settle(trouble=trouble)
        finally:
            if settlement.saved_until is not None:  # part of it kept: where, until when
                self.saved_until, self.path = settlement.saved_until, settlement.path

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

