"""Reader for the Crazyflie uSD-card deck binary log (``tools/usdlog/`` in crazyflie-firmware).

Layout (little endian)::

    0xBC | u16 version (1 or 2) | u16 number of event types
    per event type: u16 id | name\\0 | u16 count | count x "variable(t)\\0", t in B b H h I i f e
    records: u16 event id | timestamp (v1: u32 ms, v2: u64 µs) | packed values of that event
    last 4 bytes: zlib CRC32 of everything before them

:func:`read_usd` returns, per event, the timestamps in seconds (shape ``(n,)``) and one array per
variable (shape ``(n,)``, in the firmware's units; the dtype follows the type letter).
"""

from __future__ import annotations

import logging
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from groundstation.errors import SessionError
from groundstation.importers.limits import check_variables

__all__ = ["UsdEvent", "UsdFormatError", "UsdLog", "read_usd"]

log = logging.getLogger(__name__)

_MAGIC = 0xBC
#: A file that ends inside its header (a copy cut short) holds no record to salvage.
_NO_RECORDS = " (the file ends before its first record: nothing to import or salvage)"
_SALVAGE = ("; import with --allow-damaged (allow_damaged=True from Python) to salvage the "
            "records")
_TYPES = {"B": np.uint8, "b": np.int8, "H": np.uint16, "h": np.int16, "I": np.uint32,
          "i": np.int32, "f": np.float32, "e": np.float16}


class UsdFormatError(SessionError):
    """A uSD-card log is not in the deck's format or is damaged."""


@dataclass
class UsdEvent:
    """One event type of a uSD log: ``timestamps_s`` (n,) and ``values[name]`` (n,) each."""

    event_id: int
    name: str
    timestamps_s: np.ndarray
    values: dict[str, np.ndarray] = field(default_factory=dict)

    def as_array(self, names: list[str] | None = None) -> np.ndarray:
        """Variables stacked as float64 columns, shape (n_samples, n_variables)."""
        names = list(self.values) if names is None else names
        return np.column_stack([self.values[n].astype(np.float64) for n in names])


@dataclass
class UsdLog:
    """A decoded uSD log: format ``version``, whether the CRC matched, its events by name, and
    ``problems``: what was found damaged and what was done about it, one sentence each
    (empty for an intact log)."""

    path: Path
    version: int
    crc_ok: bool
    events: dict[str, UsdEvent]
    problems: list[str] = field(default_factory=list)


def _cstring(data: bytes, idx: int, *, path: Path, what: str) -> tuple[str, int]:
    end = data.find(b"\0", idx)
    if end < 0:
        raise UsdFormatError(f"{path}: header truncated inside {what} at byte {idx}{_NO_RECORDS}")
    try:
        return data[idx:end].decode("ascii"), end + 1
    except UnicodeDecodeError:
        raise UsdFormatError(f"{path}: non-ASCII {what} at byte {idx}; the header is damaged")\
            from None


def read_usd(path: str | Path, *, allow_damaged: bool = False) -> UsdLog:
    """Decode the uSD log at ``path``.

    A CRC mismatch or a truncated last record raises :class:`UsdFormatError`, unless
    ``allow_damaged`` is set: then the records that decode are returned (with ``crc_ok`` False),
    each problem is logged as a warning and listed in :attr:`UsdLog.problems`. The CRC covers
    the whole file and cannot say where it is damaged, so every record is kept as read (a
    damaged value is returned as whatever it decodes to); only damage the record layout itself
    locates (a last record cut short, a record of no declared event) drops records: those from
    that byte on.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise UsdFormatError(f"{path}: cannot read ({exc.strerror}); check the path") from None
    if len(data) < 1 or data[0] != _MAGIC:
        raise UsdFormatError(f"{path}: not a uSD-card deck log (no 0xBC header byte)")
    if len(data) < 9:  # the header byte, version, count and a CRC take 9
        raise UsdFormatError(f"{path}: only {len(data)} bytes, cut short inside its header"
                             f"{_NO_RECORDS}")
    body = data[:-4]
    (stored_crc,) = struct.unpack_from("<I", data, len(data) - 4)
    computed = zlib.crc32(body) & 0xFFFFFFFF
    crc_ok = computed == stored_crc
    problems: list[str] = []
    version, n_types = struct.unpack_from("<HH", data, 1)
    if version not in (1, 2):
        raise UsdFormatError(f"{path}: uSD log version {version} is not supported (1 or 2)")
    idx = 5
    layouts: dict[int, tuple[str, struct.Struct, list[str], str]] = {}
    seen_names: set[str] = set()
    for _ in range(n_types):
        if idx + 2 > len(body):
            raise UsdFormatError(f"{path}: header truncated in the event-type table{_NO_RECORDS}")
        (event_id,) = struct.unpack_from("<H", body, idx)
        name, idx = _cstring(body, idx + 2, path=path, what="event name")
        shown = repr(name[:64])
        if idx + 2 > len(body):
            raise UsdFormatError(f"{path}: header truncated in event {shown}{_NO_RECORDS}")
        (count,) = struct.unpack_from("<H", body, idx)
        idx += 2
        names, fmt = [], "<"
        for _ in range(count):
            entry, idx = _cstring(body, idx, path=path, what=f"variable of event {shown}")
            if len(entry) < 4 or entry[-3] != "(" or entry[-1] != ")" or entry[-2] not in _TYPES:
                raise UsdFormatError(f"{path}: bad variable entry {entry[:80]!r} in event {shown}; "
                                     "expected 'name(t)' with t in BbHhIife")
            names.append(entry[:-3])
            fmt += entry[-2]
        if event_id in layouts or name in seen_names:
            raise UsdFormatError(f"{path}: event {shown} (id {event_id}) is declared twice in "
                                 "the header; the header is damaged")
        seen_names.add(name)
        try:
            check_variables(names, where=f"{path}: event {shown}")
        except SessionError as exc:
            raise UsdFormatError(str(exc)) from None
        layouts[event_id] = (name, struct.Struct(fmt), names, fmt[1:])
    if not crc_ok:  # after the header: a file cut inside it has nothing to salvage, and its
        # header's own error says so
        msg = f"CRC mismatch (stored {stored_crc:#010x}, computed {computed:#010x})"
        if not allow_damaged:
            raise UsdFormatError(f"{path}: {msg}; the file is damaged or truncated{_SALVAGE}")
        _problem(path, problems, f"{msg}: the file is damaged or truncated, and a CRC over the "
                 "whole file cannot say where; every record that decodes is kept as read, so "
                 "any value may be wrong")
    head = struct.Struct("<HI" if version == 1 else "<HQ")
    scale = 1e-3 if version == 1 else 1e-6
    rows: dict[int, list[tuple]] = {k: [] for k in layouts}
    stamps: dict[int, list[int]] = {k: [] for k in layouts}
    end = len(body)
    while idx < end:
        if idx + head.size > end:
            _damaged(path, f"last record truncated at byte {idx}", allow_damaged, problems)
            break
        event_id, stamp = head.unpack_from(body, idx)
        layout = layouts.get(event_id)
        if layout is None:
            _damaged(path, f"record at byte {idx} has unknown event id {event_id}",
                     allow_damaged, problems, rest=end - idx)
            break
        rec = layout[1]
        if idx + head.size + rec.size > end:
            _damaged(path, f"last record truncated at byte {idx}", allow_damaged, problems)
            break
        rows[event_id].append(rec.unpack_from(body, idx + head.size))
        stamps[event_id].append(stamp)
        idx += head.size + rec.size
    events: dict[str, UsdEvent] = {}
    for event_id, (name, _rec, names, types) in layouts.items():
        cols = list(zip(*rows[event_id], strict=True)) if rows[event_id] else [()] * len(names)
        values = {n: np.asarray(col, dtype=_TYPES[t]) for n, t, col in zip(names, types, cols,
                                                                            strict=True)}
        events[name] = UsdEvent(event_id=event_id, name=name,
                                timestamps_s=np.asarray(stamps[event_id], dtype=np.float64) * scale,
                                values=values)
    return UsdLog(path=path, version=version, crc_ok=crc_ok, events=events, problems=problems)


def _problem(path: Path, problems: list[str], text: str) -> None:
    problems.append(text)
    log.warning("%s: %s", path, text)


def _damaged(path: Path, what: str, allow: bool, problems: list[str], *,
             rest: int | None = None) -> None:
    """Damage the record layout locates: refused, or (``allow``) the records from there on
    dropped (``rest`` bytes of them when more than the one record), said and listed."""
    if not allow:
        raise UsdFormatError(f"{path}: {what}{_SALVAGE}")
    dropped = "dropped" if rest is None else f"the {rest} bytes from there dropped"
    _problem(path, problems, f"{what}; {dropped}, the records before it kept")
