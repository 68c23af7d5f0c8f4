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
"""

from __future__ import annotations

import json
import logging
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

__all__ = ["SessionWriter", "check_writable", "event_rows", "standard_streams"]

log = logging.getLogger(__name__)

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
        self._file = h5py.File(self.path, "w", libver="latest")
        self._datasets: dict[str, h5py.Dataset] = {}
        self._write_header(dict(metadata or {}))
        for spec in streams:
            self._create_stream(spec)
        self._file.swmr_mode = True
        self._file.flush()
        self._last_flush = self._last_fsync = time.monotonic()
        self._fsync_thread: threading.Thread | None = None
        self.closed = False
        log.info("recording session to %s", self.path)

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
        if self.closed:
            return
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
        self._file.flush()
        now = time.monotonic()
        self._last_flush = now
        if fsync:
            self._join_fsync()
            os.fsync(self._file.id.get_vfd_handle())
            self._last_fsync = now
        elif fsync is None and now - self._last_fsync >= self.fsync_interval:
            self._fsync_in_background()
            self._last_fsync = now

    def _fsync_in_background(self) -> None:
        """``fsync`` off the caller's thread: on a slow card it can take longer than a setpoint
        period, and the caller is the flight runner. One at a time; joined before closing."""
        if self._fsync_thread is not None and self._fsync_thread.is_alive():
            return  # the previous one is still syncing: it covers these rows too, or the next
        self._fsync_thread = threading.Thread(
            target=os.fsync, args=(self._file.id.get_vfd_handle(),), name="session-fsync",
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
        """Flush everything, mark the file closed cleanly, optionally compress; returns the path."""
        if self.closed:
            return self.path
        self.flush(fsync=True)
        a = self._file.attrs
        a["closed_cleanly"] = np.int8(1)
        if duration_s is not None:
            a["duration_s"] = np.float64(duration_s)
        text = json.dumps(dict(summary or {}), sort_keys=True, default=str)
        a["summary"] = text[:4096].ljust(4096)
        self._file.flush()
        self._file.close()
        self.closed = True
        if self.compress_on_close:
            try:
                _repack(self.path)
            except Exception:  # the uncompressed file is complete: never lose it over this
                log.exception("could not compress %s; kept uncompressed", self.path)
        log.info("session closed: %s", self.path)
        return self.path

    def __enter__(self) -> SessionWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def _repack(path: Path) -> None:
    """Rewrite ``path`` with gzip-compressed chunks, atomically: into a file created exclusively
    (``O_EXCL``, random name) in the same folder and written through that descriptor, so no
    name planted beforehand (a symlink) is ever followed; then renamed over ``path``, unless
    ``path`` has become a symlink meanwhile. The rewrite keeps ``path``'s permission bits (the
    umask's, from when it was created): ``mkstemp`` makes its file owner-only."""
    st = os.lstat(path)
    mode = stat.S_IMODE(st.st_mode) & 0o777 if stat.S_ISREG(st.st_mode) else 0o600
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.",
                                    suffix=".repack")
    tmp = Path(tmp_name)
    try:
        with os.fdopen(fd, "w+b") as fh:
            os.fchmod(fh.fileno(), mode)
            with h5py.File(path, "r") as src, h5py.File(fh, "w", libver="latest") as dst:
                _copy_compressed(src, dst)
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
