"""Reader for the Crazyflie uSD-card deck binary log (``tools/usdlog/`` in crazyflie-firmware).

Layout (little endian)::

    0xBC | u16 version (1 or 2) | u16 number of event types
    per event type: u16 id | name\\0 | u16 count | count x "variable(t)\\0", t in B b H h I i f e
    records: u16 event id | timestamp (v1: u32 ms, v2: u64 µs) | packed values of that event
    last 4 bytes: zlib CRC32 of everything before them (the trailer)

The deck writes the trailer only when logging is stopped (``usd.logging`` set to 0), after the
rest of its buffer; a log cut before that (power lost, the card pulled while logging) has
none, and ends after a complete record or inside one (the buffer is written in pieces that do
not follow records). :func:`_trailer` tells them apart: the records of an intact log end 4
bytes before the file does, those of a log cut after a record where it does, and no record is
4 bytes long (the shortest, of an event with no variables in format 1, takes 6).

:func:`read_usd` returns, per event, the timestamps in seconds (shape ``(n,)``) and one array per
variable (shape ``(n,)``, in the firmware's units; the dtype follows the type letter). The
records are decoded with numpy (:mod:`groundstation.importers.usd_records`): reading a log takes
about 2.5 times its size in memory (``python -m bench usd``).
"""

from __future__ import annotations

import logging
import struct
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from groundstation.errors import SessionError
from groundstation.importers.limits import check_variables, stream_name_of_groups
from groundstation.importers.usd_records import (
    decode_fields,
    event_times,
    record_starts,
    steps_back,
    steps_repeated,
)

__all__ = ["UsdEvent", "UsdFormatError", "UsdLog", "event_block_name", "read_usd"]

log = logging.getLogger(__name__)

_MAGIC = 0xBC
#: A file that ends inside its header (a copy cut short) holds no record to salvage.
_NO_RECORDS = " (the file ends before its first record: nothing to import or salvage)"
_SALVAGE = ("; import with --allow-damaged (allow_damaged=True from Python) to salvage the "
            "records")
_TYPES = {"B": np.uint8, "b": np.int8, "H": np.uint16, "h": np.int16, "I": np.uint32,
          "i": np.int32, "f": np.float32, "e": np.float16}
_LE = {t: np.dtype(d).newbyteorder("<") for t, d in _TYPES.items()}  # as the file holds them


class UsdFormatError(SessionError):
    """A uSD-card log is not in the deck's format or is damaged."""


@dataclass
class UsdEvent:
    """One event type of a uSD log: ``timestamps_s`` (n,) and ``values[name]`` (n,) each."""

    event_id: int
    name: str
    timestamps_s: np.ndarray
    values: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def block_name(self) -> str:
        """The name of the log block (session stream) it becomes (:func:`event_block_name`)."""
        return event_block_name(event=self.name, variables=list(self.values))

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
    has_crc: bool = True
    """False for a log cut before the deck wrote its CRC trailer: nothing could be checked."""


def event_block_name(*, event: str, variables: list[str]) -> str:
    """``fixedFrequency`` (the deck's fixed-rate logging) is named after the log groups it holds
    (``stateEstimate+controller``); another event keeps its firmware name."""
    return stream_name_of_groups(variables) if event == "fixedFrequency" else event


def _cstring(data: bytes, idx: int, *, end: int, path: Path, what: str) -> tuple[str, int]:
    stop = data.find(b"\0", idx, end)
    if stop < 0:
        raise UsdFormatError(f"{path}: header truncated inside {what} at byte {idx}{_NO_RECORDS}")
    try:
        return data[idx:stop].decode("ascii"), stop + 1
    except UnicodeDecodeError:
        raise UsdFormatError(f"{path}: non-ASCII {what} at byte {idx}; the header is damaged")\
            from None


def read_usd(path: str | Path, *, allow_damaged: bool = False) -> UsdLog:
    """Decode the uSD log at ``path``.

    A CRC mismatch, a log without its CRC trailer (cut before the deck wrote it) or a
    truncated last record raises :class:`UsdFormatError`, unless ``allow_damaged`` is set:
    then the records that decode are returned (with ``crc_ok`` False), each problem is logged
    as a warning and listed in :attr:`UsdLog.problems`. The CRC covers the whole file and
    cannot say where it is damaged, so every record is kept as read (a damaged value is
    returned as whatever it decodes to); only damage the record layout itself locates (a last
    record cut short, a record of no declared event) drops records: those from that byte on.

    An event whose time goes back (beyond the format-1 tick's wrap-around, which is undone:
    :mod:`groundstation.importers.usd_records`) or, in format 2, repeats keeps every record,
    in file order; the log is not refused, and the steps are listed in
    :attr:`UsdLog.problems` (and logged).
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
    version, n_types = struct.unpack_from("<HH", data, 1)
    if version not in (1, 2):
        raise UsdFormatError(f"{path}: uSD log version {version} is not supported (1 or 2)")
    layouts, idx = _header(data, end=len(data), n_types=n_types, path=path)
    head = 6 if version == 1 else 10  # event id and timestamp
    sizes = {k: head + struct.calcsize("<" + "".join(types))
             for k, (_, _, types) in layouts.items()}
    trailer = _trailer(data, first=idx, head=head, sizes=sizes)
    problems: list[str] = []
    if not trailer.crc_ok:  # after the header: a file cut inside it has nothing to salvage,
        # and its header's own error says so
        _no_crc(path, trailer, allow=allow_damaged, problems=problems)
    if trailer.stop < trailer.end:
        _stopped(data, stop=trailer.stop, end=trailer.end, head=head, known=layouts,
                 path=path, allow=allow_damaged, problems=problems)
    events = _events(data, layouts=layouts, starts=trailer.starts, ids=trailer.ids,
                     version=version, path=path, problems=problems)
    return UsdLog(path=path, version=version, crc_ok=trailer.crc_ok, events=events,
                  problems=problems, has_crc=trailer.present)


@dataclass
class _Trailer:
    """Where a log's records end (``end``: its CRC trailer's byte, or the file's end without
    one), whether it has the trailer (``present``) and it matched, the records that decode
    (``starts``, ``ids``) and the byte they stop at (``stop``, ``end`` if none is cut)."""

    present: bool
    crc_ok: bool
    stored: int
    computed: int
    end: int
    starts: np.ndarray
    ids: np.ndarray
    stop: int


def _trailer(data: bytes, *, first: int, head: int, sizes: Mapping[int, int]) -> _Trailer:
    """Whether the file ends in the deck's CRC trailer, and where its records end.

    A matching CRC says so (a log without one matches by chance once in 2**32). Else the
    records are followed to the file's end: stopped exactly 4 bytes before it, at no declared
    event, those 4 bytes are a trailer that does not match (the file is damaged); running to
    the end, or stopped inside a record (of a declared event, cut short), the log was cut
    before the deck wrote it, and every complete record is kept. Stopped at a record of no
    declared event earlier, the record layout is damaged and cannot say: a trailer is assumed.
    """
    n = len(data)
    (stored,) = struct.unpack_from("<I", data, n - 4)
    computed = zlib.crc32(memoryview(data)[:n - 4]) & 0xFFFFFFFF  # no copy of a large file
    crc_ok = computed == stored and first <= n - 4
    end = n - 4 if crc_ok else n
    starts, ids, stop = record_starts(data, start=first, end=end, head=head, sizes=sizes)
    present = crc_ok
    if not crc_ok and stop < n:
        declared = stop + 2 <= n and (data[stop] | data[stop + 1] << 8) in sizes
        present = not declared and (stop == n - 4 or stop + head <= n - 4)
        end = n - 4 if present else n
    return _Trailer(present=present, crc_ok=crc_ok, stored=stored, computed=computed, end=end,
                    starts=starts, ids=ids, stop=stop)


def _no_crc(path: Path, trailer: _Trailer, *, allow: bool, problems: list[str]) -> None:
    """A CRC that does not match, or none: refused, or (``allow``) said."""
    if trailer.present:
        msg = f"CRC mismatch (stored {trailer.stored:#010x}, computed {trailer.computed:#010x})"
        if not allow:
            raise UsdFormatError(f"{path}: {msg}; the file is damaged or truncated{_SALVAGE}")
        _problem(path, problems, f"{msg}: the file is damaged or truncated, and a CRC over "
                 "the whole file cannot say where; every record that decodes is kept as read, "
                 "so any value may be wrong")
        return
    where = ("inside a record" if trailer.stop < trailer.end else
             "after a complete record" if len(trailer.starts) else "after its header")
    msg = (f"no CRC trailer: the file ends {where}, cut before the deck wrote its CRC (it "
           "does when logging is stopped; power lost or the card pulled while logging?)")
    if not allow:
        advice = _SALVAGE if len(trailer.starts) else ": no record, nothing to import or salvage"
        raise UsdFormatError(f"{path}: {msg}{advice}")
    _problem(path, problems, f"{msg}; nothing can be checked, every complete record is kept "
             "as read")


def _header(data: bytes, *, end: int, n_types: int,
            path: Path) -> tuple[dict[int, tuple[str, list[str], list[str]]], int]:
    """The event types, ``{event id: (name, variables, type letters)}``, and the first record's
    byte."""
    idx = 5
    layouts: dict[int, tuple[str, list[str], list[str]]] = {}
    seen_names: set[str] = set()
    for _ in range(n_types):
        if idx + 2 > end:
            raise UsdFormatError(f"{path}: header truncated in the event-type table{_NO_RECORDS}")
        (event_id,) = struct.unpack_from("<H", data, idx)
        name, idx = _cstring(data, idx + 2, end=end, path=path, what="event name")
        shown = repr(name[:64])
        if idx + 2 > end:
            raise UsdFormatError(f"{path}: header truncated in event {shown}{_NO_RECORDS}")
        (count,) = struct.unpack_from("<H", data, idx)
        idx += 2
        names, types = [], []
        for _ in range(count):
            entry, idx = _cstring(data, idx, end=end, path=path,
                                  what=f"variable of event {shown}")
            if len(entry) < 4 or entry[-3] != "(" or entry[-1] != ")" or entry[-2] not in _TYPES:
                raise UsdFormatError(f"{path}: bad variable entry {entry[:80]!r} in event {shown}; "
                                     "expected 'name(t)' with t in BbHhIife")
            names.append(entry[:-3])
            types.append(entry[-2])
        if event_id in layouts or name in seen_names:
            raise UsdFormatError(f"{path}: event {shown} (id {event_id}) is declared twice in "
                                 "the header; the header is damaged")
        seen_names.add(name)
        try:
            check_variables(names, where=f"{path}: event {shown}")
        except SessionError as exc:
            raise UsdFormatError(str(exc)) from None
        layouts[event_id] = (name, names, types)
    return layouts, idx


def _stopped(data: bytes, *, stop: int, end: int, head: int, known: Mapping[int, object],
             path: Path, allow: bool, problems: list[str]) -> None:
    """What ends the records at byte ``stop`` before ``end``: refused, or (``allow``) said."""
    event_id = data[stop] | data[stop + 1] << 8 if stop + head <= end else None
    if event_id is None or event_id in known:
        _damaged(path, f"last record truncated at byte {stop}", allow, problems)
    else:
        _damaged(path, f"record at byte {stop} has unknown event id {event_id}", allow, problems,
                 rest=end - stop)


def _events(data: bytes, *, layouts: Mapping[int, tuple[str, list[str], list[str]]],
            starts: np.ndarray, ids: np.ndarray, version: int, path: Path,
            problems: list[str]) -> dict[str, UsdEvent]:
    """Each declared event's records (at ``starts``, of event ``ids``) as arrays, in header
    order; the steps back of its time, and its repeated stamps, said in ``problems``."""
    stamp = "<u4" if version == 1 else "<u8"
    order = np.argsort(ids, kind="stable")  # the records of each event, in file order
    sorted_ids = ids[order]
    events: dict[str, UsdEvent] = {}
    for event_id, (name, names, types) in layouts.items():
        lo, hi = np.searchsorted(sorted_ids, [event_id, event_id + 1])
        mine = starts[order[lo:hi]]
        layout = np.dtype([("id", "<u2"), ("t", stamp),
                           *((f"v{k}", _LE[t]) for k, t in enumerate(types))])
        cols = decode_fields(data, starts=mine, layout=layout, out={
            "t": np.dtype(stamp[1:]), **{f"v{k}": _TYPES[t] for k, t in enumerate(types)}})
        stamps = cols.pop("t")
        seconds, wraps = event_times(stamps, version=version)
        if wraps:
            log.info("%s: event %r: the 32-bit ms tick wrapped around %d time(s); undone",
                     path, name, wraps)
        for text in _time_texts(_named(event=name, variables=names), stamps=stamps,
                                seconds=seconds, starts=mine, version=version):
            _problem(path, problems, text)
        events[name] = UsdEvent(event_id=event_id, name=name, timestamps_s=seconds,
                                values={n: cols[f"v{k}"] for k, n in enumerate(names)})
    return events


def _named(*, event: str, variables: list[str]) -> str:
    """``event 'fixedFrequency' (block 'g')``: an event and, if named otherwise, its block."""
    block = event_block_name(event=event, variables=variables)
    return f"event {event!r}" + (f" (block {block!r})" if block != event else "")


def _time_texts(named: str, *, stamps: np.ndarray, seconds: np.ndarray, starts: np.ndarray,
                version: int) -> list[str]:
    """What is wrong with one event's time, a sentence each: its steps back (how many, the
    first, the largest) and, in format 2, its repeated stamps (legitimate in format 1:
    :mod:`groundstation.importers.usd_records`). Every row is kept either way."""
    texts = []
    back = steps_back(seconds)
    if len(back):
        k = int(back[0])
        size = seconds[back - 1] - seconds[back]
        text = (f"{named}: time goes back at {len(back)} of its {len(seconds) - 1} steps, "
                f"first at row {k} (from 0; byte {int(starts[k])} of the file): "
                f"{seconds[k]:.6f} s after {seconds[k - 1]:.6f} s, {size[0]:.6g} s back")
        if len(back) > 1:
            text += f"; the largest {float(size.max()):.6g} s back"
        texts.append(text + "; every row kept, in file order")
    same = steps_repeated(stamps) if version == 2 else ()
    if len(same):
        k = int(same[0])
        texts.append(f"{named}: {len(same)} row(s) repeat the time of the row before, first "
                     f"at row {k} (from 0; byte {int(starts[k])} of the file): "
                     f"{seconds[k]:.6f} s; every row kept, the later row's values hold at that "
                     "time")
    return texts


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
