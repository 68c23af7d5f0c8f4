"""Turn logs written by other tools (uSD-card deck, cfclient CSV) into session files.

The result is an ordinary session (``docs/session-format.md``) so everything downstream
(``groundstation info``, ``sysid``) works on it. What an imported log cannot know is left out:
no setpoints, no link samples, one phase ``log`` (kind ``imported``) covering the whole log.

Times: these logs carry only the Crazyflie's clock, so ``host_time`` is the firmware time in
seconds (full resolution, e.g. the µs of uSD format 2) and ``fw_time_ms`` the same instant in
whole milliseconds (24-bit wrapped, as a log packet carries it). The root attribute
``time_base`` says so; ``source_format`` and ``source_files`` say where the data came from.
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from groundstation.errors import SessionError
from groundstation.importers.cfclient_csv import CsvLog, read_cfclient_csv
from groundstation.importers.usd import read_usd
from groundstation.session import SessionWriter, check_writable, standard_streams
from groundstation.session_schema import CFLIB_TYPES, log_block_spec

__all__ = ["ImportedBlock", "csv_to_session", "usd_to_session", "write_imported_session"]

log = logging.getLogger(__name__)

_WRAP = 1 << 24
_CFLIB_OF_DTYPE = {"uint8": "uint8_t", "int8": "int8_t", "uint16": "uint16_t",
                   "int16": "int16_t", "uint32": "uint32_t", "int32": "int32_t",
                   "float32": "float", "float16": "FP16", "float64": "double"}
TIME_BASE = "imported: host_time is the firmware time in seconds (no host clock in the log)"


@dataclass(frozen=True)
class ImportedBlock:
    """One log block to write: ``timestamps_s`` (n,) firmware seconds, ``values[var]`` (n,),
    ``ctypes[var]`` the cflib type name of each variable ``group.name``."""

    name: str
    timestamps_s: np.ndarray
    values: Mapping[str, np.ndarray]
    ctypes: Mapping[str, str]

    @property
    def period_s(self) -> float:
        """Median sample period in seconds, rounded to 0.1 ms (0.01 s for a single sample)."""
        if len(self.timestamps_s) < 2:
            return 0.01
        return round(float(np.median(np.diff(self.timestamps_s))), 4) or 0.001


def _safe_name(name: str, taken: set[str]) -> str:
    base = re.sub(r"[^A-Za-z0-9_.-]", "_", name) or "block"
    out, i = base, 2
    while out in taken or out in {s.name for s in standard_streams()}:
        out, i = f"{base}_{i}", i + 1
    taken.add(out)
    return out


def write_imported_session(*, blocks: Sequence[ImportedBlock], out: str | os.PathLike[str],
                           metadata: Mapping[str, Any]) -> Path:
    """Write ``blocks`` as one session at ``out`` (module docstring); returns the path."""
    blocks = [b for b in blocks if len(b.timestamps_s)]
    if not blocks:
        raise SessionError(f"{out}: nothing to import (every log block is empty)")
    out = Path(out)
    check_writable(out)
    taken: set[str] = set()
    specs = []
    for b in blocks:
        variables = [(v, b.ctypes[v]) for v in b.values]
        bad = [t for _, t in variables if t not in CFLIB_TYPES]
        if bad:
            raise SessionError(f"block {b.name!r}: unsupported types {bad}")
        specs.append(log_block_spec(name=_safe_name(b.name, taken), variables=variables,
                                    period_s=b.period_s))
    t_first = min(float(b.timestamps_s[0]) for b in blocks)
    t_last = max(float(b.timestamps_s[-1]) for b in blocks)
    meta = {"time_base": TIME_BASE, "uri": "", **metadata}
    start_ns = int(meta.pop("start_time_ns", 0)) or None
    with SessionWriter(out, streams=[*specs, *standard_streams()], metadata=meta,
                       start_time_ns=start_ns) as w:
        w.phase(t=t_first, phase_id=0, name="log", kind="imported")
        w.event(t=t_first, text=f"imported from {meta.get('source_files')}", source="import")
        for spec, b in zip(specs, blocks, strict=True):
            ds = np.zeros(len(b.timestamps_s), dtype=spec.dtype)
            ds["host_time"] = b.timestamps_s
            ds["fw_time_ms"] = np.round(b.timestamps_s * 1000.0).astype(np.int64) % _WRAP
            for f, var in zip(spec.fields[2:], b.values, strict=True):
                ds[f.name] = b.values[var]
            w.extend(spec.name, ds.tolist())
        w.close(duration_s=t_last, summary={
            "imported": True, "rows": {s.name: len(b.timestamps_s)
                                       for s, b in zip(specs, blocks, strict=True)}})
    log.info("imported %d block(s) into %s", len(blocks), out)
    return out


def usd_to_session(*, source: str | os.PathLike[str], out: str | os.PathLike[str],
                   allow_damaged: bool = False) -> Path:
    """Convert a uSD-card deck log (one block per non-empty event type) to a session."""
    usd = read_usd(source, allow_damaged=allow_damaged)
    blocks = []
    for ev in usd.events.values():
        if not len(ev.timestamps_s):
            log.info("%s: event %r has no records; skipped", source, ev.name)
            continue
        ctypes = {k: _CFLIB_OF_DTYPE[v.dtype.name] for k, v in ev.values.items()}
        blocks.append(ImportedBlock(ev.name, ev.timestamps_s, ev.values, ctypes))
    src = Path(source)
    meta = {"source_format": f"crazyflie uSD-card deck log, format {usd.version}",
            "source_files": [str(src)], "crc_ok": int(usd.crc_ok),
            "start_time_ns": src.stat().st_mtime_ns}
    return write_imported_session(blocks=blocks, out=out, metadata=meta)


def csv_to_session(*, sources: Sequence[str | os.PathLike[str]],
                   out: str | os.PathLike[str]) -> Path:
    """Convert a set of cfclient "log to file" CSVs (one per log block) to one session."""
    if not sources:
        raise SessionError(f"{out}: no CSV files given; pass the block CSVs of one flight")
    logs: list[CsvLog] = [read_cfclient_csv(p) for p in sources]
    blocks = [ImportedBlock(c.name, c.timestamps_s, c.values, c.ctypes) for c in logs]
    meta = {"source_format": "cfclient log-to-file CSV",
            "source_files": [str(Path(p)) for p in sources],
            "start_time_ns": min(Path(p).stat().st_mtime_ns for p in sources)}
    return write_imported_session(blocks=blocks, out=out, metadata=meta)
