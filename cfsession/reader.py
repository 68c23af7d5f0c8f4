"""Reading session files, including ones left behind by a crashed writer.

:func:`open_session` loads every stream into memory (a flight is a few MB) and returns a
:class:`Session`. Every file is opened through :func:`cfsession.guard.open_cut`, read-only
and never in SWMR mode (where HDF5 retries a bad checksum for over a minute). A file whose writer
died (its superblock still flagged open for writing) is read into memory, at most
:data:`~cfsession.guard.MAX_UNCLEAN_BYTES`, and that private copy, its flags cleared, is opened
in the ordinary mode; the file on disk is not changed, and :attr:`Session.problems` says the data
end at the last flush. Rows that were allocated but never written (NaN ``host_time``) are
dropped; a stream whose chunks cannot all be read is read as far as it goes and listed in
:attr:`Session.problems`. A file cut short (a copy interrupted, a card pulled) is read from a
zero-padded private copy the same way; the rows of every chunk lying even partly beyond the cut
are left out (listed per stream), and a stream whose metadata lay there is listed as unreadable
(its root attributes lost, the file is still read if its streams are session streams). So is
the damage an importer found in the log it imported (root attribute ``source_problems``).
:func:`warn_problems` repeats them as warnings.
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

from cfsession.errors import SessionError, did_you_mean
from cfsession.guard import (
    Cut,
    check_dataset,
    file_size,
    hard_links,
    lost_chunks,
    open_cut,
    read_attrs,
    short_error,
)
from cfsession.schema import (
    SCHEMA_NAME,
    SCHEMA_VERSION,
    events_spec,
    link_spec,
    phases_spec,
    setpoints_spec,
)

__all__ = ["Event", "Gap", "PhaseWindow", "Session", "StreamData", "open_session",
           "warn_problems"]

log = logging.getLogger(__name__)

_WRAP = 1 << 24  # log packets carry a 24-bit millisecond tick
_LEVEL_NAMES = {1: "debug", 2: "info", 3: "warning", 4: "error", 5: "critical"}
_REQUIRED = {spec.name: {f.name: np.dtype(f.dtype).kind for f in spec.fields}
             for spec in (events_spec(), phases_spec(), setpoints_spec(), link_spec())}
"""The fields the reader's own methods use in the standard streams, with their numpy kinds."""
_KIND_OK = {"S": ("S", "text"), "u": ("biu", "integers"), "i": ("biu", "integers"),
            "f": ("biuf", "numbers")}
"""For a field's kind in the schema: the kinds a file may store it as, and their name (an
integer field stored as floats holds NaN, which ``int()`` refuses; a text field stored as
numbers has no text)."""


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
class StreamData:
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
        self, path: Path, meta: dict[str, Any], streams: dict[str, StreamData], problems: list[str]
    ) -> None:
        self.path = path
        self.meta = meta
        self.streams = streams
        self.problems = problems

    @property
    def schema_version(self) -> int:
        """The session schema it was written with; 0 when unknown (the root attributes lay
        beyond the end of a file cut short)."""
        return int(self.meta.get("schema_version", 0))

    @property
    def imported(self) -> bool:
        """A log imported from elsewhere (uSD card, cfclient CSV): it has no host clock, so its
        ``host_time`` holds the firmware's seconds (root attribute ``time_base`` says so)."""
        return str(self.meta.get("time_base", "")).startswith("imported")

    @property
    def closed_cleanly(self) -> bool:
        """False when the writer died (the file holds what was flushed before)."""
        return bool(self.meta.get("closed_cleanly", 0))

    def __getitem__(self, name: str) -> StreamData:
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
        except (ValueError, RecursionError):  # damaged, or nested too deep to be ours
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
            hint = did_you_mean(name_or_kind, [*names, *kinds])
            raise SessionError(f"{self.path}: no phase {name_or_kind!r}{hint}; phases are "
                               f"{names} (kinds {kinds})")
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


def _read_dataset(ds: h5py.Dataset, problems: list[str], name: str,
                  lost: list[int] | None = None) -> np.ndarray:
    """Read all rows; on a damaged chunk, keep the rows before it and record the problem.
    The chunks starting at the rows in ``lost`` (beyond the end of a file cut short:
    :func:`cfsession.guard.lost_chunks`) are not read; their rows are counted in one problem."""
    n = ds.shape[0]
    chunk = (ds.chunks or (max(n, 1),))[0]
    lost = [start for start in lost or [] if start < n]
    parts: list[np.ndarray] = []
    pos = 0
    for start in [*lost, n]:
        if start > pos:
            part, whole = _read_rows(ds, pos, start, problems, name)
            parts.append(part)
            if not whole:
                break
        pos = start + chunk
    if lost:
        rows = sum(min(start + chunk, n) - start for start in lost)
        problems.append(f"stream {name!r}: unreadable from row {lost[0]} ({rows} rows lay "
                        "beyond the cut)")
    data = np.concatenate(parts) if parts else np.empty(0, dtype=ds.dtype)
    written = ~np.isnan(data["host_time"])
    if not written.all():
        log.info("%s: dropping %d unwritten rows", name, int((~written).sum()))
    return data[written]


def _read_rows(ds: h5py.Dataset, start: int, stop: int, problems: list[str],
               name: str) -> tuple[np.ndarray, bool]:
    """Rows ``start:stop`` (``start`` on a chunk boundary) and whether all were read: on a
    damaged chunk, the rows before it, the problem recorded."""
    try:
        return ds[start:stop], True
    except Exception:  # h5py raises OSError / RuntimeError / KeyError on corrupt chunks
        chunk = (ds.chunks or (1024,))[0]
        parts = []
        for at in range(start, stop, chunk):
            try:
                parts.append(ds[at : min(at + chunk, stop)])
            except Exception as exc:
                problems.append(f"stream {name!r}: unreadable from row {at} ({exc})")
                break
        else:
            return np.concatenate(parts) if parts else np.empty(0, dtype=ds.dtype), True
        return np.concatenate(parts) if parts else np.empty(0, dtype=ds.dtype), False


def _meta_problems(meta: dict[str, Any], p: Path, problems: list[str], *,
                   lost: bool = False) -> None:
    """Check the root attributes a reader relies on: schema, schema_version (one-line
    :class:`SessionError`; not when they were ``lost`` beyond the end of a file cut short);
    wrongly typed optional ones are dropped and listed in problems."""
    if not lost and meta.get("schema") != SCHEMA_NAME:
        model = str(meta.get("format", "")).endswith("StateSpaceModel")
        what = ": a model file (sysid compare, sysid export read it)" if model else ""
        raise SessionError(f"{p}: HDF5 file but not a flight session (no '{SCHEMA_NAME}' "
                           f"schema){what}")
    version = meta.get("schema_version")
    if isinstance(version, float) and version.is_integer():
        version = int(version)
    if lost and "schema_version" not in meta:
        pass
    elif not isinstance(version, int) or isinstance(version, bool) or version < 1:
        raise SessionError(f"{p}: schema_version {version!r} is not a session schema version "
                           f"(1 to {SCHEMA_VERSION}); the file is damaged or not a session")
    elif version > SCHEMA_VERSION:
        raise SessionError(f"{p}: written with session schema {version}, this groundstation "
                           f"reads up to {SCHEMA_VERSION}; upgrade groundstation")
    else:
        meta["schema_version"] = version
    for key, kinds in (*((k, (int, float)) for k in _NUMBER_ATTRS), ("start_time_ns", (int,)),
                       ("protocol_version", (int,)), *((k, (str,)) for k in _TEXT_ATTRS)):
        if key in meta and (not isinstance(meta[key], kinds) or isinstance(meta[key], bool)):
            problems.append(f"attribute {key!r} has the wrong type; ignored")
            del meta[key]
    for key, value in meta.items():  # other writers' keys: plain values, as JSON has them
        if isinstance(value, np.ndarray):
            meta[key] = value.tolist()
    if isinstance(meta.get("summary"), str):
        meta["summary"] = meta["summary"].rstrip()
    problems.extend(_source_problems(meta))


_MIN_PERIOD_S = 1e-7
"""Shortest ``period_s`` read: what an importer writes is rounded to 0.1 µs (a period of
1e-300 s made ``info`` expect a 300-digit number of rows, and sysid refuse the grid)."""
_NUMBER_ATTRS = ("closed_cleanly", "duration_s", "setpoint_rate_hz")
_TEXT_ATTRS = ("summary", "uri", "firmware", "plan_name", "plan_text", "software_version",
               "start_time_iso", "tag", "params", "phase_table", "rate_limits", "time_base",
               "plan_parameters", "source_format", "source_files", "source_mtime_iso")
"""Root attributes of the schema (docs/session-format.md) that are numbers or text: one of
another type (an array where ``uri`` is text) is dropped and listed in problems, not shown."""

_MAX_SOURCE_PROBLEMS = 20
"""At most this many of an imported log's problems are listed (the rest counted)."""


def _source_problems(meta: dict[str, Any]) -> list[str]:
    """The damage an importer found in the log it read (root attribute ``source_problems``, a
    JSON list of sentences), each prefixed ``imported log:``; a uSD import whose CRC did not
    match (``crc_ok`` 0) from before that attribute gets a sentence of its own."""
    raw = meta.get("source_problems")
    texts: list[str] = []
    if isinstance(raw, str) and raw.strip():
        try:
            texts = json.loads(raw)
        except (ValueError, RecursionError):
            texts = ["root attribute 'source_problems' is damaged"]
        if not isinstance(texts, list) or not all(isinstance(t, str) for t in texts):
            texts = ["root attribute 'source_problems' is damaged"]
    if not texts and meta.get("crc_ok") in (0, False):
        texts = ["its CRC did not match (imported with --allow-damaged); the CRC cannot "
                 "locate the damage, so any value may be wrong"]
    out = [f"imported log: {t[:500]}" for t in texts[:_MAX_SOURCE_PROBLEMS]]
    if len(texts) > _MAX_SOURCE_PROBLEMS:
        out.append(f"imported log: {len(texts) - _MAX_SOURCE_PROBLEMS} more problems")
    return out


def _stream(name: str, group: h5py.Group, *, p: Path, size: int, problems: list[str],
            cut: Cut | None = None) -> StreamData | None:
    """One stream group, checked (:mod:`cfsession.guard`) and read; ``None`` (listed in
    ``problems`` when it is a damaged stream) when it is not read: a standard stream lacking a
    field the reader uses, or holding one of the wrong type, is left out, the others read."""
    where = f"{p}: stream {name!r}"
    members = dict(hard_links(group, where=where))
    ds = members.get("data")
    if not isinstance(ds, h5py.Dataset):
        return None
    check_dataset(ds, where=where, file_size=size)
    lost = lost_chunks(ds, cut)
    names = list(ds.dtype.names or ())
    required = {**_REQUIRED.get(name, {}), "fw_time_ms": "u"}
    missing = [f for f in required if f not in names and f != "fw_time_ms"]
    if missing:
        problems.append(f"stream {name!r}: not read: it lacks field(s) {missing}")
        return None
    for fname, kind in required.items():
        stored = ds.dtype.fields[fname][0] if fname in names else None
        ok, what = _KIND_OK[kind]
        if stored is not None and stored.kind not in ok:
            problems.append(f"stream {name!r}: not read: field {fname!r} has type {stored}, "
                            f"where a session stream holds {what}")
            return None
    dattrs = read_attrs(ds, where=where, problems=problems)
    gattrs = {k: _decode(v) for k, v in read_attrs(group, where=where, problems=problems).items()}

    def labels(key: str) -> dict[str, str]:
        raw = _decode(dattrs.get(key, []))
        raw = raw if isinstance(raw, list) and all(isinstance(x, str) for x in raw) else []
        return dict(zip(names, raw + [""] * (len(names) - len(raw)), strict=False))

    period = gattrs.get("period_s")
    if period is not None and not (isinstance(period, int | float) and not isinstance(period, bool)
                                   and _MIN_PERIOD_S <= period < 1e6):
        problems.append(f"stream {name!r}: period_s {period!r} ignored")
        period = None
    kind = gattrs.get("kind", "")
    return StreamData(name=name, kind=kind if isinstance(kind, str) else "",
                  data=_read_dataset(ds, problems, name, lost), units=labels("units"),
                  sources=labels("sources"), period_s=period, attrs=gattrs)


def open_session(path: str | os.PathLike[str]) -> Session:
    """Read a session file; one-line :class:`SessionError` if it is not a readable session
    (or was crafted to read elsewhere or exhaust memory: :mod:`cfsession.guard`).
    A damaged file is read as far as it goes, its damage listed in :attr:`Session.problems`;
    so is a file cut short (its tail lost: :func:`cfsession.guard.open_cut`), where what lay
    beyond the cut (rows, a stream's metadata, the root attributes) is listed as lost."""
    p = Path(path)
    if not p.exists() and not p.is_symlink():
        raise SessionError(f"{p}: no such file")
    f, clean_superblock, cut = open_cut(p)
    problems: list[str] = [] if cut is None else [
        f"file {cut} (a copy or a card cut short): what lay beyond is lost"]
    streams: dict[str, StreamData] = {}
    root_lost = False

    def unreadable(name: str, exc: Exception) -> None:
        problems.append(f"stream {name!r}: unreadable ({short_error(exc)}; its metadata lay "
                        "beyond the cut)")

    try:
        with f:
            size = file_size(f, p)
            meta, root_lost = _root_attrs(f, p, cut, problems)
            _meta_problems(meta, p, problems, lost=root_lost)
            for name, obj in hard_links(f, where=str(p),
                                        unreadable=None if cut is None else unreadable):
                if not isinstance(obj, h5py.Group):
                    continue
                try:
                    stream = _stream(name, obj, p=p, size=size, problems=problems, cut=cut)
                except SessionError:
                    raise
                except Exception as exc:
                    if cut is None:
                        raise
                    unreadable(name, exc)
                    continue
                if stream is not None:
                    streams[name] = stream
    except SessionError:
        raise
    except Exception as exc:  # HDF5 errors on damaged metadata: never a traceback
        log.debug("reading %s", p, exc_info=True)
        where = "" if cut is None else f"{cut}; "
        raise SessionError(f"{p}: damaged beyond repair ({where}{type(exc).__name__}: "
                           f"{str(exc).splitlines()[0][:200] if str(exc) else ''})") from None
    if root_lost and not streams:
        raise SessionError(f"{p}: damaged beyond repair ({cut}: no session attributes and no "
                           "stream before the cut)")
    if not clean_superblock or (not meta.get("closed_cleanly", 0) and not root_lost):
        problems.append("writer did not close the file (crash or kill): data up to the last flush")
    return Session(p, meta, streams, problems)


def _root_attrs(f: h5py.File, p: Path, cut: Cut | None,
                problems: list[str]) -> tuple[dict[str, Any], bool]:
    """The root attributes, and whether the session's own (``schema``) lay beyond the end of
    a file cut short: then the file is read as a session if it has session streams."""
    if cut is None:
        return {k: _decode(v) for k, v in read_attrs(f, where=str(p),
                                                     problems=problems).items()}, False
    try:
        names = list(f.attrs.keys())
        found: list[str] = []
        meta = {k: _decode(v) for k, v in read_attrs(f, where=str(p), problems=found).items()}
    except SessionError:
        raise
    except Exception as exc:
        log.debug("root attributes of %s", p, exc_info=True)
        problems.append(f"root attributes unreadable ({short_error(exc)}): they lay beyond the "
                        "cut; uri, start time, plan and summary are unknown")
        return {}, True
    problems.extend(found)
    return meta, "schema" in names and "schema" not in meta


def warn_problems(session: Session, logger: logging.Logger | None = None) -> None:
    """Log each of ``session.problems`` (what ``groundstation info`` lists) as one warning
    naming the file, ``FILE: problem: ...``: every command that reads a session on to
    something else (identification, a replay, an export) repeats them, so damaged or
    crash-truncated data is never used in silence."""
    for problem in session.problems:
        (logger or log).warning("%s: problem: %s", session.path, problem)


Stream = StreamData
"""Former name of :class:`StreamData` (kept for callers; ``sysid.Stream`` is another class)."""
