"""Turn logs written by other tools (uSD-card deck, cfclient CSV) into session files.

The result is an ordinary session (``docs/session-format.md``, "Imported sessions") so everything
downstream (``groundstation info``, ``sysid``) works on it. What an imported log cannot know is
left out: no setpoints or link streams, no wall-clock start. The airborne segments found in the
log (:mod:`groundstation.importers.airborne`) are its phases ``airborne-1``, ``airborne-2``, ...
with ``ground-0``, ``ground-1``, ... around them; a log without any has one phase ``log``.

Times: these logs carry only the Crazyflie's clock, so ``host_time`` is the firmware time in
seconds (full resolution, e.g. the µs of uSD format 2) and ``fw_time_ms`` the same instant in
whole milliseconds (24-bit wrapped, as a log packet carries it). The root attribute
``time_base`` says so; ``source_format`` and ``source_files`` say where the data came from.

A session is written to a private folder created next to ``out`` and renamed into place at the
end: a failure leaves nothing behind, and an existing file is replaced only with ``force``.
"""

from __future__ import annotations

import logging
import os
import re
import shutil
import tempfile
import time
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cfsession.schema import (
    CFLIB_TYPES,
    Field,
    StreamSpec,
    events_spec,
    phases_spec,
    unit_of,
)
from cfsession.writer import SessionWriter
from groundstation.errors import SessionError
from groundstation.importers.airborne import Segment, find_segments
from groundstation.importers.cfclient_csv import CsvFormatError, CsvLog, read_cfclient_csv
from groundstation.importers.limits import check_variables, stream_name_of_groups
from groundstation.importers.usd import read_usd

__all__ = ["ImportedBlock", "csv_to_session", "field_names", "stream_name_of_groups",
           "usd_to_session", "write_imported_session"]

log = logging.getLogger(__name__)

_WRAP = 1 << 24
_CFLIB_OF_DTYPE = {"uint8": "uint8_t", "int8": "int8_t", "uint16": "uint16_t",
                   "int16": "int16_t", "uint32": "uint32_t", "int32": "int32_t",
                   "float32": "float", "float16": "FP16", "float64": "double"}
_RESERVED_FIELDS = frozenset({"host_time", "fw_time_ms"})
_RESERVED_STREAMS = frozenset({"setpoints", "events", "phases", "link"})
_MAX_BLOCKS = 256
_ROWS_AT_ONCE = 1 << 15
"""Rows handed to the session writer at once (as tuples: about 1 kB each in Python)."""
TIME_BASE = "imported: host_time is the firmware time in seconds (no host clock in the log)"
NO_START = "unknown (the log carries no wall-clock time)"


class OutputFolderError(SessionError):
    """The ``--out`` folder takes no files (permissions, a file in the way): no import into it
    can succeed, so a batch stops at the first."""


@dataclass(frozen=True)
class ImportedBlock:
    """One log block to write: ``timestamps_s`` (n,) firmware seconds, ``values[var]`` (n,),
    ``ctypes[var]`` the cflib type name of each variable ``group.name``; ``source_event`` the
    uSD event it came from ('' for a CSV)."""

    name: str
    timestamps_s: np.ndarray
    values: Mapping[str, np.ndarray]
    ctypes: Mapping[str, str]
    source_event: str = ""

    @property
    def period_s(self) -> float:
        """Mean sample period in seconds, over the steps that are no gap (at most 1.5 median
        steps), rounded to 0.1 µs (0.01 s for a single sample). Not the median: a logger
        ticking at 101.2 Hz on a millisecond clock steps 9 or 10 ms, and a median of 10 ms (or
        a rounding to 0.1 ms) would make the rows expected over the log's span too few.
        Repeated time stamps (steps of 0) are no sample period: a log repeating every one
        read as 1 ms, 8991 rows "dropped" and a 1 ms grid for the identification."""
        steps = np.diff(self.timestamps_s)
        steps = steps[steps > 0]
        if not len(steps):
            return 0.01
        median = float(np.median(steps))
        period = float(np.mean(steps[(steps > 0) & (steps <= 1.5 * median)]))
        return round(period, 7)


def _safe_stream_name(name: str, taken: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9_+-]", "_", name)[:64] or "block"
    out, i = base, 2
    while out in taken or out in _RESERVED_STREAMS:
        out, i = f"{base}_{i}", i + 1
    taken.add(out)
    return out


def field_names(variables: Sequence[str]) -> list[str]:
    """Unique dataset field names for ``group.name`` variables, linear time.

    ``motor.m1`` -> ``m1``; a short name two variables share, or a reserved one (``host_time``,
    ``fw_time_ms``), becomes the full name with ``.`` as ``_``; characters other than letters,
    digits and ``_`` become ``_``; a name still taken gets ``_2``, ``_3``, ... The variables must
    have passed :func:`~groundstation.importers.limits.check_variables`.
    """
    shorts = [re.sub(r"\W", "_", v.split(".", 1)[-1], flags=re.ASCII) for v in variables]
    counts = Counter(shorts)
    taken = set(_RESERVED_FIELDS)
    out = []
    for var, short in zip(variables, shorts, strict=True):
        clash = counts[short] > 1 or short in _RESERVED_FIELDS
        base = re.sub(r"\W", "_", var, flags=re.ASCII) if clash else short
        name, i = base, 2
        while name in taken:
            name, i = f"{base}_{i}", i + 1
        taken.add(name)
        out.append(name)
    return out


def _spec(block: ImportedBlock, name: str) -> StreamSpec:
    variables = list(block.values)
    fields = [Field("host_time", "<f8", "s", "firmware time, seconds (imported log)"),
              Field("fw_time_ms", "<u4", "ms", "Crazyflie firmware tick (24-bit, wraps)")]
    for var, fname in zip(variables, field_names(variables), strict=True):
        ctype = block.ctypes[var]
        if ctype not in CFLIB_TYPES:
            raise SessionError(f"block {block.name!r}: variable {var!r} has the unsupported "
                               f"type {ctype!r}")
        fields.append(Field(fname, CFLIB_TYPES[ctype], unit_of(var), var))
    attrs: dict[str, str | float | int] = {"cflib_types": ",".join(block.ctypes[v]
                                                                   for v in variables)}
    if block.source_event:
        attrs["source_event"] = block.source_event
    return StreamSpec(name=name, kind="log", fields=tuple(fields), period_s=block.period_s,
                      description=f"imported log block '{block.name}'", attrs=attrs)


def _rows(*, spec: StreamSpec, block: ImportedBlock, start: int, stop: int) -> np.ndarray:
    """Rows ``start:stop`` of ``block`` in the stream's fields."""
    t = block.timestamps_s[start:stop]
    ds = np.zeros(len(t), dtype=spec.dtype)
    ds["host_time"] = t
    ds["fw_time_ms"] = np.round(t * 1000.0).astype(np.int64) % _WRAP
    for f, var in zip(spec.fields[2:], block.values, strict=True):
        ds[f.name] = block.values[var][start:stop]
    return ds


def _phase_rows(segments: Sequence[Segment], t_first: float,
                t_last: float) -> list[tuple[float, str, str]]:
    """``(start, name, kind)`` per phase: ``ground-k`` around ``airborne-k``, else ``log``."""
    if not segments:
        return [(t_first, "log", "imported")]
    rows = [(t_first, "ground-0", "ground")] if segments[0].start_s > t_first else []
    for k, seg in enumerate(segments, start=1):
        rows.append((seg.start_s, f"airborne-{k}", "airborne"))
        if seg.end_s < t_last:
            rows.append((seg.end_s, f"ground-{k}", "ground"))
    return rows


def _iso(ns: int) -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(ns / 1e9))


def _files_text(files: Sequence[str]) -> str:
    names = ", ".join(str(f) for f in files[:5])
    return names + (f" and {len(files) - 5} more" if len(files) > 5 else "")


def _publish(tmp: Path, out: Path, *, force: bool) -> None:
    """Move the finished ``tmp`` to ``out``: never over an existing path unless ``force``."""
    if force:
        os.replace(tmp, out)
        return
    try:
        os.link(tmp, out)  # fails if out exists, even as a dangling symlink
    except FileExistsError:
        raise SessionError(f"{out}: already exists; pass --force to replace it") from None
    except OSError:  # a file system without hard links
        if os.path.lexists(out):
            raise SessionError(f"{out}: already exists; pass --force to replace it") from None
        os.rename(tmp, out)


def write_imported_session(*, blocks: Sequence[ImportedBlock], out: str | os.PathLike[str],
                           metadata: Mapping[str, Any], force: bool = False) -> Path:
    """Write ``blocks`` as one session at ``out`` (module docstring); returns the path.

    ``metadata`` needs ``source_format`` and ``source_files``; ``source_mtime_ns`` (the source
    file's modification time) is recorded as ``source_mtime_iso``; ``source_problems`` (a list
    of sentences: the damage the source's reader found and what it did about it) is kept as a
    root attribute, which the session reader lists in ``Session.problems``, and each is a
    warning event. With ``force`` an existing ``out`` is replaced (only once the new session is
    complete).
    """
    out = Path(out)
    blocks = [b for b in blocks if len(b.timestamps_s)]
    if not blocks:
        raise SessionError(f"{out}: nothing to import (every log block is empty)")
    if len(blocks) > _MAX_BLOCKS:
        raise SessionError(f"{out}: {len(blocks)} log blocks; at most {_MAX_BLOCKS} fit one "
                           "session (import fewer files at once)")
    here = Path(os.path.realpath(out.parent)) / out.name  # the entry a replace would hit
    if any(Path(f) == here for f in metadata.get("source_files", [])):
        raise SessionError(f"{out}: is the log being imported; write the session to another "
                           "--out folder")
    if os.path.lexists(out) and (not force or out.is_dir()):
        raise SessionError(f"{out}: already exists; "
                           + ("a folder" if out.is_dir() else "pass --force to replace it"))
    taken: set[str] = set()
    specs = []
    for b in blocks:
        check_variables(list(b.values), where=f"block {b.name!r}")
        specs.append(_spec(b, _safe_stream_name(b.name, taken)))
    t_first = min(float(b.timestamps_s[0]) for b in blocks)
    t_last = max(float(b.timestamps_s[-1]) for b in blocks)
    segments, how = find_segments(blocks)
    meta = {k: v for k, v in metadata.items() if k != "source_mtime_ns"}
    if "source_mtime_ns" in metadata:
        meta["source_mtime_iso"] = _iso(int(metadata["source_mtime_ns"]))
    meta = {"time_base": TIME_BASE, "uri": "", **meta, "start_time_iso": NO_START}
    files = [str(f) for f in meta.get("source_files", [])]
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        tmpdir = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".importing",
                                       dir=out.parent))
    except OSError as exc:
        raise OutputFolderError(f"{out.parent}: cannot write there ({exc.strerror}); choose "
                                "another --out folder") from None
    try:
        tmp = tmpdir / out.name
        with SessionWriter(tmp, streams=[*specs, events_spec(), phases_spec()], metadata=meta,
                           start_time_ns=0) as w:
            for i, (t, name, kind) in enumerate(_phase_rows(segments, t_first, t_last)):
                w.phase(t=t, phase_id=min(i, 32767), name=name, kind=kind)
            w.event(t=t_first, source="import",
                    text=f"imported from {meta.get('source_format', 'a log')}: "
                         f"{_files_text(files)}")
            for problem in meta.get("source_problems", []):
                w.event(t=t_first, level="warning", source="import",
                        text=f"damaged source: {problem}")
            w.event(t=t_first, source="import", text=how)
            for spec, b in zip(specs, blocks, strict=True):
                for a in range(0, len(b.timestamps_s), _ROWS_AT_ONCE):
                    rows = _rows(spec=spec, block=b, start=a, stop=a + _ROWS_AT_ONCE)
                    w.extend(spec.name, rows.tolist())
                    w.flush()  # the writer takes tuples: a few at a time, not the whole log
            w.close(duration_s=t_last - t_first, summary={
                "imported": True,
                "rows": {s.name: len(b.timestamps_s) for s, b in zip(specs, blocks, strict=True)},
                "airborne_s": [[s.start_s, s.end_s] for s in segments]})
        _publish(tmp, out, force=force)
    except SessionError:
        raise
    except (OSError, ValueError) as exc:  # h5py: header too large, disk full, ...
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SessionError(f"{out}: cannot write the session ({first})") from None
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    log.info("imported %d block(s) into %s", len(blocks), out)
    return out


def usd_to_session(*, source: str | os.PathLike[str], out: str | os.PathLike[str],
                   allow_damaged: bool = False, force: bool = False) -> Path:
    """Convert a uSD-card deck log (one block per non-empty event type) to a session.

    The ``fixedFrequency`` event is named after the log groups it holds; other events keep
    their firmware name (``docs/session-format.md``).
    """
    usd = read_usd(source, allow_damaged=allow_damaged)
    blocks = []
    for ev in usd.events.values():
        if not len(ev.timestamps_s):
            log.info("%s: event %r has no records; skipped", source, ev.name)
            continue
        ctypes = {k: _CFLIB_OF_DTYPE[v.dtype.name] for k, v in ev.values.items()}
        blocks.append(ImportedBlock(ev.block_name, ev.timestamps_s, ev.values, ctypes,
                                    source_event=ev.name))
    src = Path(source)
    crc = ("CRC ok" if usd.crc_ok else "CRC MISMATCH" if usd.has_crc else
           "NO CRC, cut before the deck wrote it")  # what was done: usd.problems
    meta = {"source_format": f"crazyflie uSD-card deck log, format {usd.version} ({crc})",
            "source_files": [str(src.resolve())], "crc_ok": int(usd.crc_ok),
            "source_mtime_ns": src.stat().st_mtime_ns,
            **({"source_problems": usd.problems} if usd.problems else {})}
    return write_imported_session(blocks=blocks, out=out, metadata=meta, force=force)


def csv_to_session(*, sources: Sequence[str | os.PathLike[str]],
                   out: str | os.PathLike[str], force: bool = False) -> Path:
    """Convert a set of cfclient "log to file" CSVs (one per log block) to one session."""
    if not sources:
        raise SessionError(f"{out}: no CSV files given; pass the block CSVs of one flight")
    logs: list[CsvLog] = [read_cfclient_csv(p) for p in sources]
    if not any(len(c.timestamps_s) for c in logs):
        raise CsvFormatError(f"{_files_text([str(c.path) for c in logs])}: header only, no "
                             "samples; nothing to import")
    for c in logs:
        if not len(c.timestamps_s):
            log.warning("%s: %s", c.path, c.problems[-1])
    blocks = [ImportedBlock(c.name, c.timestamps_s, c.values, c.ctypes) for c in logs]
    problems = [f"{c.path.name}: {p}" for c in logs for p in c.problems]
    meta = {"source_format": "cfclient log-to-file CSV",
            "source_files": [str(Path(p).resolve()) for p in sources],
            "source_mtime_ns": min(Path(p).stat().st_mtime_ns for p in sources),
            **({"source_problems": problems} if problems else {})}
    return write_imported_session(blocks=blocks, out=out, metadata=meta, force=force)

