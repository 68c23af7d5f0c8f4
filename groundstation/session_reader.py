"""Reading session files, including ones left behind by a crashed writer.

:func:`open_session` loads every stream into memory (a flight is a few MB) and returns a
:class:`Session`. A file whose writer died is opened in SWMR-read mode; rows that were allocated
but never written (NaN ``host_time``) are dropped; a stream whose chunks cannot all be read is
read as far as it goes and listed in :attr:`Session.problems`.
"""

from __future__ import annotations

import json
import logging
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import h5py
import numpy as np

from groundstation.errors import SessionError
from groundstation.session_schema import SCHEMA_NAME, SCHEMA_VERSION

__all__ = ["Event", "Gap", "PhaseWindow", "Session", "Stream", "open_session"]

log = logging.getLogger(__name__)

_WRAP = 1 << 24  # log packets carry a 24-bit millisecond tick
_LEVEL_NAMES = {1: "debug", 2: "info", 3: "warning", 4: "error", 5: "critical"}


@dataclass(frozen=True)
class Gap:
    """Log packets missing between two received ones (firmware time, seconds)."""

    stream: str
    start_s: float
    end_s: float
    missing: int


@dataclass(frozen=True)
class PhaseWindow:
    """A phase of the flight on the host clock: ``[start_s, end_s)``."""

    phase_id: int
    name: str
    kind: str
    start_s: float
    end_s: float


@dataclass(frozen=True)
class Event:
    t: float
    level: str
    source: str
    text: str


def _decode(value: Any) -> Any:
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    if isinstance(value, np.ndarray) and value.dtype.kind in "OSU":
        return [_decode(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return value.item()
    return value


@dataclass(frozen=True)
class Stream:
    """One stream's rows as a numpy structured array ``data`` (shape ``(n_rows,)``)."""

    name: str
    kind: str
    data: np.ndarray
    units: dict[str, str]
    sources: dict[str, str]
    period_s: float | None = None
    attrs: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.data)

    @property
    def time(self) -> np.ndarray:
        """Host receive/send time, seconds since session start, shape ``(n_rows,)``."""
        return self.data["host_time"]

    @property
    def value_fields(self) -> list[str]:
        """Fields other than the timestamps."""
        return [f for f in self.data.dtype.names if f not in ("host_time", "fw_time_ms")]

    @property
    def fw_time_s(self) -> np.ndarray | None:
        """Firmware time in seconds with 24-bit wrap-arounds undone, or None if not a log stream."""
        if "fw_time_ms" not in self.data.dtype.names:
            return None
        ms = self.data["fw_time_ms"].astype(np.int64)
        if len(ms) > 1:
            wraps = np.concatenate([[0], np.cumsum(np.diff(ms) < -(_WRAP // 2))])
            ms = ms + wraps * _WRAP
        return ms / 1000.0

    def values(self, fields: list[str] | None = None) -> np.ndarray:
        """Value columns as float64, shape ``(n_rows, n_fields)``."""
        names = fields or self.value_fields
        missing = [f for f in names if f not in self.data.dtype.names]
        if missing:
            raise SessionError(
                f"stream {self.name!r} has no field(s) {missing}; has {self.value_fields}"
            )
        return (
            np.column_stack([self.data[f].astype(np.float64) for f in names])
            if names
            else (np.empty((len(self.data), 0)))
        )

    def gaps(self, *, tolerance: float = 0.5) -> list[Gap]:
        """Runs of dropped packets: firmware-time steps longer than (1 + tolerance) periods."""
        t = self.fw_time_s
        if t is None or not self.period_s or len(t) < 2:
            return []
        dt = np.diff(t)
        idx = np.flatnonzero(dt > self.period_s * (1.0 + tolerance))
        return [
            Gap(self.name, float(t[i]), float(t[i + 1]), round(dt[i] / self.period_s) - 1)
            for i in idx
        ]


class Session:
    """A session file read into memory. ``problems`` lists anything found damaged."""

    def __init__(
        self, path: Path, meta: dict[str, Any], streams: dict[str, Stream], problems: list[str]
    ) -> None:
        self.path = path
        self.meta = meta
        self.streams = streams
        self.problems = problems

    @property
    def schema_version(self) -> int:
        return int(self.meta["schema_version"])

    @property
    def closed_cleanly(self) -> bool:
        """False when the writer died (the file holds what was flushed before)."""
        return bool(self.meta.get("closed_cleanly", 0))

    def __getitem__(self, name: str) -> Stream:
        try:
            return self.streams[name]
        except KeyError:
            raise SessionError(
                f"{self.path}: no stream {name!r}; streams are {sorted(self.streams)}"
            ) from None

    def __contains__(self, name: str) -> bool:
        return name in self.streams

    def json_meta(self, key: str, default: Any = None) -> Any:
        """A metadata attribute stored as JSON (params, phase table, summary), decoded."""
        raw = self.meta.get(key)
        if not isinstance(raw, str) or not raw.strip():
            return default
        try:
            return json.loads(raw)
        except json.JSONDecodeError:
            return default

    @property
    def duration(self) -> float:
        """Seconds from session start to the last row of any stream."""
        ends = [float(np.nanmax(s.time)) for s in self.streams.values() if len(s)]
        return max(ends, default=0.0)

    def gaps(self) -> list[Gap]:
        """Dropped-packet gaps of every log stream."""
        return [g for s in self.streams.values() if s.kind == "log" for g in s.gaps()]

    def dropped(self) -> dict[str, int]:
        """Dropped log packets per log stream, from firmware timestamp gaps."""
        return {
            name: sum(g.missing for g in s.gaps())
            for name, s in self.streams.items()
            if s.kind == "log"
        }

    def phases(self) -> list[PhaseWindow]:
        """Phase windows in order; the last one ends at the end of the session."""
        if "phases" not in self.streams:
            return []
        d = self.streams["phases"].data
        end = self.duration
        out = []
        for i, row in enumerate(d):
            stop = float(d["host_time"][i + 1]) if i + 1 < len(d) else end
            out.append(
                PhaseWindow(
                    int(row["phase_id"]),
                    _decode(row["name"]),
                    _decode(row["kind"]),
                    float(row["host_time"]),
                    stop,
                )
            )
        return out

    def phase_window(self, name_or_kind: str) -> tuple[float, float]:
        """Host-time span from the first to the last phase with this name or kind."""
        hits = [p for p in self.phases() if name_or_kind in (p.name, p.kind)]
        if not hits:
            names = sorted({p.name for p in self.phases()})
            kinds = sorted({p.kind for p in self.phases()})
            raise SessionError(f"{self.path}: no phase {name_or_kind!r}; phases are {names} "
                               f"(kinds {kinds})")
        return hits[0].start_s, hits[-1].end_s

    def events(self) -> list[Event]:
        """Events with continued texts joined (bytes first, so split characters survive)."""
        if "events" not in self.streams:
            return []
        parts: list[tuple[float, str, str, bytes]] = []
        for row in self.streams["events"].data:
            raw = bytes(row["text"])
            if row["cont"] and parts:
                t, level, source, prev = parts[-1]
                parts[-1] = (t, level, source, prev + raw)
            else:
                level = _LEVEL_NAMES.get(int(row["level"]), "info")
                parts.append((float(row["host_time"]), level, _decode(row["source"]), raw))
        return [Event(t, lv, src, raw.decode("utf-8", errors="replace"))
                for t, lv, src, raw in parts]


def _read_dataset(ds: h5py.Dataset, problems: list[str], name: str) -> np.ndarray:
    """Read all rows; on a damaged chunk, keep the rows before it and record the problem."""
    try:
        data = ds[()]
    except Exception:  # h5py raises OSError / RuntimeError / KeyError on corrupt chunks
        chunk = (ds.chunks or (1024,))[0]
        parts = []
        for start in range(0, ds.shape[0], chunk):
            try:
                parts.append(ds[start : start + chunk])
            except Exception as exc:
                problems.append(f"stream {name!r}: unreadable from row {start} ({exc})")
                break
        data = np.concatenate(parts) if parts else np.empty(0, dtype=ds.dtype)
    written = ~np.isnan(data["host_time"])
    if not written.all():
        log.info("%s: dropping %d unwritten rows", name, int((~written).sum()))
    return data[written]


def _stored_eof(path: Path) -> int | None:
    """End-of-file address recorded in a version 2/3 superblock (None if not such a file)."""
    with open(path, "rb") as fh:
        head = fh.read(48)
    if head[:8] != b"\x89HDF\r\n\x1a\n" or head[8] not in (2, 3) or head[9] != 8:
        return None
    return int.from_bytes(head[28:36], "little")


def _open_h5(path: Path) -> h5py.File:
    """Open read-only; a file whose SWMR writer died is opened in SWMR-read mode.

    A truncated file must never reach the SWMR reader: HDF5 retries failed metadata reads
    there without end, so the stored end-of-file is checked against the real size first.
    """
    try:
        return h5py.File(path, "r")
    except OSError as exc:
        msg = str(exc)
    if "signature" in msg:
        raise SessionError(f"{path}: not an HDF5 file, so not a flight session") from None
    if "already open for write" in msg:
        eof = _stored_eof(path)
        if eof is not None and path.stat().st_size < eof:
            raise SessionError(
                f"{path}: damaged beyond repair (truncated at {path.stat().st_size} of {eof} bytes)"
            )
        try:
            return h5py.File(path, "r", libver="latest", swmr=True)
        except OSError as exc:
            msg = str(exc)
    first = msg.split("(")[0].strip() or "unreadable"
    detail = msg[msg.find("(") + 1 : msg.rfind(")")] if "(" in msg else ""
    raise SessionError(f"{path}: damaged beyond repair ({first}: {detail})") from None


def open_session(path: str | os.PathLike[str]) -> Session:
    """Read a session file; one-line :class:`SessionError` if it is not a readable session."""
    p = Path(path)
    if not p.exists():
        raise SessionError(f"{p}: no such file")
    if p.is_dir():
        raise SessionError(f"{p}: is a folder, not a session file")
    with _open_h5(p) as f:
        meta = {k: _decode(v) for k, v in f.attrs.items()}
        if meta.get("schema") != SCHEMA_NAME:
            raise SessionError(
                f"{p}: HDF5 file but not a flight session (no '{SCHEMA_NAME}' schema)"
            )
        version = int(meta.get("schema_version", 0))
        if version > SCHEMA_VERSION:
            raise SessionError(
                f"{p}: written with session schema {version}, this groundstation reads up to "
                f"{SCHEMA_VERSION}; upgrade groundstation"
            )
        if isinstance(meta.get("summary"), str):
            meta["summary"] = meta["summary"].rstrip()
        problems: list[str] = []
        streams: dict[str, Stream] = {}
        for name, group in f.items():
            if not isinstance(group, h5py.Group) or "data" not in group:
                continue
            ds = group["data"]
            names = list(ds.dtype.names or ())
            units = dict(
                zip(names, _decode(ds.attrs.get("units", [""] * len(names))), strict=False)
            )
            sources = dict(
                zip(names, _decode(ds.attrs.get("sources", [""] * len(names))), strict=False)
            )
            gattrs = {k: _decode(v) for k, v in group.attrs.items()}
            streams[name] = Stream(
                name=name,
                kind=str(gattrs.get("kind", "")),
                data=_read_dataset(ds, problems, name),
                units=units,
                sources=sources,
                period_s=gattrs.get("period_s"),
                attrs=gattrs,
            )
    if not meta.get("closed_cleanly", 0):
        problems.append("writer did not close the file (crash or kill): data up to the last flush")
    return Session(p, meta, streams, problems)
