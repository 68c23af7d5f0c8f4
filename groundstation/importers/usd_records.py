"""The record stream of a uSD-card log decoded with numpy, for :mod:`groundstation.importers.usd`:
where each record starts, then one array per field, with no Python object per record or value
(an hour at 1 kHz is millions of records).

A record is ``u16 event id | timestamp | values``, its size fixed by its event, so where a
record starts is known only from the one before. Over a run of records of one size (a
``fixedFrequency`` log, the deck's usual mode, is one run, whatever other events its header
declares) the starts are ``first + k * size``, checked at once (:func:`record_starts`); where
events of several sizes interleave, a pass in Python collects them (8 bytes a record). Each
event's records are then read through a structured dtype: a strided view of the file's bytes
when they are evenly spaced, else gathered about :data:`CHUNK_BYTES` at a time.

Timestamps (:func:`event_times`): a format-1 log stamps records with the 32-bit millisecond
tick, which wraps after 49.7 days; a step across 2**32 of at most :data:`WRAP_STEP_MS` is that
wrap and is undone. Format 2 stamps 64-bit microseconds, which never wrap.

Two records of one event with one stamp (:func:`steps_repeated`) are legitimate in format 1:
its stamp is the 1 kHz FreeRTOS tick, and two records fall in one tick when an event is raised
twice within a millisecond, or when ``fixedFrequency`` logs at 1 kHz (in step with the
stabilizer loop, which the IMU paces, not the tick; or catching up after a late tick). Format 2
stamps each record from ``usecTimestamp()`` (a 1 MHz timer) as ``usddeck.c`` buffers it, which
takes longer than a microsecond, so a repeated stamp there is damage, flagged as time going
back is.
"""

from __future__ import annotations

from array import array
from collections.abc import Iterator, Mapping

import numpy as np

__all__ = ["CHUNK_BYTES", "WRAP_STEP_MS", "decode_fields", "event_times", "record_starts",
           "steps_back", "steps_repeated"]

CHUNK_BYTES = 1 << 20
"""Bytes of records gathered at once when an event's records are unevenly spaced (the index
array that gathers them is eight times that)."""
WRAP_STEP_MS = 60_000
"""The longest step across the 32-bit ms tick's wrap taken as the wrap (a minute). A longer
"step" back from near 2**32 to near 0 is more likely a damaged stamp, and undoing it as a wrap
would move the rest of the event 49.7 days on; it is flagged as time going back instead."""
_TICK = 1 << 32
_SHORT_RUN = 64
"""Records of one size below which a run counts as short: records of several sizes interleave
there, and the next stretch is walked one by one, twice as long as the one before."""


def record_starts(data: bytes, *, start: int, end: int, sizes: Mapping[int, int],
                  head: int) -> tuple[np.ndarray, np.ndarray, int]:
    """``(starts, event ids, stop)`` of the records in ``data[start:end]`` that decode whole:
    ``sizes[event_id]`` is a record's size, header (``head`` bytes) included. ``stop`` is
    ``end``, or the byte of the first record cut short or of an event not in ``sizes``.

    Runs of records of one size are found at once (:func:`_run`); between runs the records
    are walked one by one, for longer each time a run turns out short (records of several
    sizes interleaved), so neither way costs much where the other fits."""
    size_of = np.zeros(1 << 16, dtype=np.int64)
    size_of[list(sizes)] = list(sizes.values())
    one_size: dict[int, np.ndarray] = {}  # size: which event ids have it (those met)
    size_list = size_of.tolist()
    pieces: list[np.ndarray] = []
    i, walk_for = start, _SHORT_RUN
    while i + head <= end:
        size = size_list[data[i] | data[i + 1] << 8]
        if not size or i + size > end:
            break
        if size not in one_size:
            one_size[size] = size_of == size
        n = _run(data, start=i, end=end, size=size, same=one_size[size])
        pieces.append(i + size * np.arange(n, dtype=np.int64))
        i += size * n
        walk_for = _SHORT_RUN if n >= _SHORT_RUN else min(2 * walk_for, 1 << 20)
        walked, i = _walk(data, start=i, end=end, size_of=size_list, head=head, limit=walk_for)
        pieces.append(walked)
    starts = np.concatenate(pieces) if pieces else np.zeros(0, dtype=np.int64)
    u8 = np.frombuffer(data, np.uint8)
    ids = u8[starts].astype(np.uint16) | (u8[starts + 1].astype(np.uint16) << 8)
    return starts, ids, i


def _run(data: bytes, *, start: int, end: int, size: int, same: np.ndarray) -> int:
    """How many records from ``start`` on (the first one decodes) are of events of ``size``
    (``same[event_id]``): the event ids at ``start + k * size`` checked at once, in stretches
    doubling from :data:`_SHORT_RUN` (a short run costs little, a long one few steps)."""
    room = (end - start) // size
    n, stretch = 0, _SHORT_RUN
    while n < room:
        m = min(stretch, room - n)
        ids = np.ndarray((m,), dtype="<u2", buffer=data, offset=start + n * size,
                         strides=(size,))
        bad = np.flatnonzero(~same[ids])
        if len(bad):
            return n + int(bad[0])
        n, stretch = n + m, 2 * stretch
    return n


def _walk(data: bytes, *, start: int, end: int, size_of: list[int], head: int,
          limit: int) -> tuple[np.ndarray, int]:
    """Up to ``limit`` records one after the other (the only work done per record): their
    starts and the byte after them."""
    starts = array("q")
    push = starts.append
    i = start
    for _ in range(limit):
        if i + head > end:
            break
        size = size_of[data[i] | data[i + 1] << 8]
        if not size or i + size > end:
            break
        push(i)
        i += size
    return np.frombuffer(starts, dtype=np.int64) if starts else np.zeros(0, np.int64), i


def _chunks(data: bytes, *, starts: np.ndarray,
            layout: np.dtype) -> Iterator[tuple[int, np.ndarray]]:
    """``(first record, records)`` over the records at ``starts``, read as ``layout``."""
    n = len(starts)
    steps = np.diff(starts)
    if n and (n == 1 or np.all(steps == steps[0])):  # evenly spaced: a view of the bytes
        stride = int(steps[0]) if n > 1 else layout.itemsize
        yield 0, np.ndarray((n,), dtype=layout, buffer=data, offset=int(starts[0]),
                            strides=(stride,))
        return
    u8 = np.frombuffer(data, np.uint8)
    width = np.arange(layout.itemsize)
    chunk = max(1, CHUNK_BYTES // layout.itemsize)
    for a in range(0, n, chunk):
        raw = u8[starts[a:a + chunk, None] + width]  # (records, itemsize), C order
        yield a, raw.view(layout)[:, 0]


def decode_fields(data: bytes, *, starts: np.ndarray, layout: np.dtype,
                  out: Mapping[str, np.dtype]) -> dict[str, np.ndarray]:
    """Field ``name`` of ``layout`` (one record, a structured dtype) over the records at
    ``starts``, as a new array of dtype ``out[name]``, for each name in ``out``."""
    fields = {name: np.empty(len(starts), dtype=dt) for name, dt in out.items()}
    for a, recs in _chunks(data, starts=starts, layout=layout):
        for name, col in fields.items():
            col[a:a + len(recs)] = recs[name]
    for col in fields.values():
        _quiet_nans(col)
    return fields


def _quiet_nans(col: np.ndarray) -> None:
    """NaNs as a record-by-record read through Python floats gives them, in place: a float32
    NaN quieted (a signalling NaN, which a corrupt or random value can be, makes every later
    cast warn), a float16 NaN the plain one of its sign."""
    if col.dtype == np.float32:
        bits = col.view(np.uint32)
        bits[np.isnan(col)] |= np.uint32(0x0040_0000)
    elif col.dtype == np.float16:
        bits = col.view(np.uint16)
        nan = np.isnan(col)
        bits[nan] = np.uint16(0x7E00) | (bits[nan] & np.uint16(0x8000))


def event_times(stamps: np.ndarray, *, version: int) -> tuple[np.ndarray, int]:
    """``(seconds, wraps undone)`` of one event's raw timestamps (format 1: uint32 ms, format
    2: uint64 µs); module docstring."""
    if version != 1 or len(stamps) < 2:
        return stamps.astype(np.float64) * (1e-3 if version == 1 else 1e-6), 0
    ticks = stamps.astype(np.int64)
    across = (ticks[1:] - ticks[:-1]) % _TICK  # the step forward, across 2**32 if need be
    wraps = (ticks[1:] < ticks[:-1]) & (across <= WRAP_STEP_MS)
    if wraps.any():
        ticks[1:] += _TICK * np.cumsum(wraps)
    return ticks.astype(np.float64) * 1e-3, int(wraps.sum())


def steps_back(seconds: np.ndarray) -> np.ndarray:
    """Rows whose time is before the row's before them (indices of the later row)."""
    return np.flatnonzero(seconds[1:] < seconds[:-1]) + 1


def steps_repeated(stamps: np.ndarray) -> np.ndarray:
    """Rows whose stamp equals the row's before them (indices of the later row)."""
    return np.flatnonzero(stamps[1:] == stamps[:-1]) + 1
