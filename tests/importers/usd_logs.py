"""uSD-card deck logs for tests and benchmarks: written record by record (small, any content) or
with numpy (tens of MB in a second), and read back the straightforward way, one record at a time
with :mod:`struct` (as ``tools/usdlog/cfusdlog.py`` in the firmware does): the reference the
reader's arrays are compared with, and the baseline of ``python -m bench usd``.

An event layout is ``(event_id, name, [(variable, type letter), ...])``; a record is
``(event_id, timestamp, values)`` with the timestamp in the format's ticks (ms for version 1,
µs for version 2) and the values a tuple, or the record's value bytes as they are.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Sequence

import numpy as np

__all__ = ["ALL_TYPES", "Layout", "build_usd", "reference_read", "same_values", "synthetic_usd",
           "usd_header", "with_crc"]

Layout = tuple[int, str, Sequence[tuple[str, str]]]

ALL_TYPES: list[Layout] = [
    (7, "fixedFrequency", [("g.u8", "B"), ("g.i8", "b"), ("g.u16", "H"), ("g.i16", "h"),
                           ("g.u32", "I"), ("g.i32", "i"), ("g.f", "f"), ("g.e", "e")]),
    (9, "ev", [("x.e", "e")]),
    (300, "mark", []),  # an event with no variables: its records are the header alone
    (4, "never", [("n.f", "f")]),  # declared, no records
]
"""Every type letter the format has, events of three record sizes, one of none, one empty."""

_LE = {"B": "u1", "b": "i1", "H": "<u2", "h": "<i2", "I": "<u4", "i": "<i4", "f": "<f4",
       "e": "<f2"}


def usd_header(*, version: int, events: Sequence[Layout]) -> bytes:
    """The header: 0xBC, version, the event types and their variables (a variable's name as
    text, or as bytes for names no firmware would write)."""
    out = bytearray(b"\xbc" + struct.pack("<HH", version, len(events)))
    for event_id, name, variables in events:
        out += struct.pack("<H", event_id) + name.encode() + b"\0"
        out += struct.pack("<H", len(variables))
        out += b"".join((v if isinstance(v, bytes) else v.encode()) + f"({t})".encode() + b"\0"
                        for v, t in variables)
    return bytes(out)


def with_crc(body: bytes) -> bytes:
    """``body`` and its CRC-32, as the deck ends a log when logging is switched off."""
    return body + struct.pack("<I", zlib.crc32(body) & 0xFFFFFFFF)


def build_usd(*, version: int, events: Sequence[Layout],
              records: Sequence[tuple[int, int, tuple | bytes]], crc: bool = True) -> bytes:
    """A log of ``records`` written one by one with :mod:`struct`, and its CRC (``crc``)."""
    fmts = {eid: "<" + "".join(t for _, t in variables) for eid, _, variables in events}
    stamp = "<HI" if version == 1 else "<HQ"
    body = bytearray(usd_header(version=version, events=events))
    for event_id, t, values in records:
        body += struct.pack(stamp, event_id, t)
        body += values if isinstance(values, bytes) else struct.pack(fmts[event_id], *values)
    return with_crc(bytes(body)) if crc else bytes(body)


def _record_dtype(version: int, variables: Sequence[tuple[str, str]]) -> np.dtype:
    fields = [("id", "<u2"), ("t", "<u4" if version == 1 else "<u8")]
    return np.dtype(fields + [(f"v{k}", _LE[t]) for k, (_, t) in enumerate(variables)])


def synthetic_usd(*, version: int = 2, seconds: float, rate_hz: float = 1000.0,
                  mixed: bool = False, seed: int = 0) -> bytes:
    """A flight-test-sized log written with numpy: event 1 ``fixedFrequency`` (20 variables,
    80-byte records) at ``rate_hz``; with ``mixed``, also event 2 ``estPose`` (7 floats) at a
    rate ``rate_hz / 3.7`` that does not divide it, so the two interleave irregularly. Event 3
    is declared with no records, as the firmware declares ``activeMarkerModeChanged``. Values
    are random bytes (any float bit pattern, NaNs included); timestamps rise with jitter."""
    rng = np.random.default_rng(seed)
    tick = 1e3 if version == 1 else 1e6
    fixed = [*((f"motor.m{i}", "H") for i in range(1, 5)),
             *((f"stateEstimate.{a}", "f") for a in ("x", "y", "z", "roll", "pitch", "yaw")),
             *((f"gyro.{a}", "f") for a in "xyz"), *((f"acc.{a}", "f") for a in "xyz"),
             *((f"controller.cmd_{a}", "f") for a in ("thrust", "roll", "pitch")),
             ("pm.vbatMV", "H")]
    layouts: list[Layout] = [(1, "fixedFrequency", fixed),
                             (3, "activeMarkerModeChanged", [("activeMarker.mode", "B")])]
    if mixed:
        layouts.append((2, "estPose", [(f"pose.{a}", "f") for a in ("x", "y", "z", "qx", "qy",
                                                                   "qz", "qw")]))
    parts, times = [], []
    rates = {1: rate_hz, 2: rate_hz / 3.7}  # event 3: none
    for event_id, _name, variables in layouts:
        if event_id not in rates:
            continue
        rate = rates[event_id]
        n = int(seconds * rate)
        t = np.round((np.arange(n) / rate + rng.uniform(0, 0.2 / rate, n)) * tick + 5 * tick)
        dt = _record_dtype(version, variables)
        recs = np.frombuffer(rng.bytes(n * dt.itemsize), dtype=dt).copy()
        recs["id"], recs["t"] = event_id, t.astype(np.uint64)
        parts.append(recs)
        times.append(t)
    order = np.argsort(np.concatenate(times), kind="stable")
    which = np.concatenate([np.full(len(p), k) for k, p in enumerate(parts)])[order]
    sizes = np.array([p.dtype.itemsize for p in parts])[which]
    offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    out = np.empty(int(sizes.sum()), np.uint8)
    for k, p in enumerate(parts):
        raw = p.view(np.uint8).reshape(len(p), p.dtype.itemsize)
        at = offsets[which == k]
        for a in range(0, len(p), 1 << 16):
            out[at[a:a + (1 << 16), None] + np.arange(p.dtype.itemsize)] = raw[a:a + (1 << 16)]
    return with_crc(usd_header(version=version, events=layouts) + out.tobytes())


def reference_read(data: bytes) -> dict[str, tuple[np.ndarray, dict[str, np.ndarray]]]:
    """``{event: (raw timestamps, {variable: values})}`` of an intact log, or of a damaged one
    up to its first record that does not decode, one record at a time."""
    version, n_types = struct.unpack_from("<HH", data, 1)
    idx, layouts = 5, {}
    for _ in range(n_types):
        (event_id,) = struct.unpack_from("<H", data, idx)
        end = data.index(b"\0", idx + 2)
        name = data[idx + 2:end].decode()
        (count,) = struct.unpack_from("<H", data, end + 1)
        idx, entries = end + 3, []
        for _ in range(count):
            end = data.index(b"\0", idx)
            entries.append(data[idx:end].decode())
            idx = end + 1
        fmt = struct.Struct("<" + "".join(e[-2] for e in entries))
        layouts[event_id] = (name, fmt, [e[:-3] for e in entries],
                             [np.dtype(_LE[e[-2]].lstrip("<")) for e in entries])
    head = struct.Struct("<HI" if version == 1 else "<HQ")
    rows: dict[int, list[tuple]] = {k: [] for k in layouts}
    stamps: dict[int, list[int]] = {k: [] for k in layouts}
    body = data[:-4]
    while idx + head.size <= len(body):
        event_id, t = head.unpack_from(body, idx)
        if event_id not in layouts or idx + head.size + layouts[event_id][1].size > len(body):
            break
        rows[event_id].append(layouts[event_id][1].unpack_from(body, idx + head.size))
        stamps[event_id].append(t)
        idx += head.size + layouts[event_id][1].size
    out = {}
    for event_id, (name, _fmt, names, dtypes) in layouts.items():
        cols = list(zip(*rows[event_id], strict=True)) or [()] * len(names)
        out[name] = (np.asarray(stamps[event_id], dtype=np.uint64),
                     {n: np.asarray(c, dtype=d) for n, c, d in zip(names, cols, dtypes,
                                                                   strict=True)})
    return out


def same_values(ours: np.ndarray, ref: np.ndarray) -> bool:
    """``ours`` holds what ``ref`` (:func:`reference_read`) does: dtype, shape, every value's
    bytes; a NaN where ``ref`` has one, quiet (a signalling NaN makes every later cast warn),
    its payload as it may be (how a Python float carries one differs between versions)."""
    if ours.dtype != ref.dtype or ours.shape != ref.shape:
        return False
    if ours.dtype.kind != "f":
        return ours.tobytes() == ref.tobytes()
    nan = np.isnan(ref)
    quiet = {4: 0x0040_0000, 2: 0x0200}[ours.itemsize]
    bits = ours.view(f"u{ours.itemsize}")
    return bool(np.array_equal(np.isnan(ours), nan) and np.all(bits[nan] & quiet)
                and ours[~nan].tobytes() == ref[~nan].tobytes())
