"""Reader for the Crazyflie client's "log to file" CSV files (``cfclient/utils/logdatawriter.py``).

The client writes one CSV per log block, named ``<block>-YYYYmmddTHH-MM-SS.csv`` in a folder
``logdata/YYYYmmddTHH-MM-SS/``::

    Timestamp,stabilizer.roll,stabilizer.pitch
    123456,0.51,-1.2
    123466,0.49,-1.3

The timestamp is the Crazyflie's millisecond tick carried by the log packet; every other column
is one log variable ``group.name`` as ``str(value)``. :func:`read_cfclient_csv` returns the
timestamps in seconds (shape ``(n,)``, 24-bit wrap-arounds undone) and one float64 array per
variable (shape ``(n,)``).
A last line cut short (the client was killed while writing) is dropped with a warning; a file
without samples (the block logged nothing) is an empty block, said in ``problems``; any other
malformed line, a non-finite value (``nan``, ``inf``) or a timestamp going backwards (beyond the
24-bit wrap-around) is a one-line :class:`CsvFormatError` naming the file and line.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from groundstation.errors import SessionError
from groundstation.importers.limits import check_variables

__all__ = ["CsvFormatError", "CsvLog", "block_name_of", "read_cfclient_csv"]

log = logging.getLogger(__name__)

_STAMP_SUFFIX = re.compile(r"-\d{8}T\d{2}-\d{2}-\d{2}$")
_INT32 = 2**31
_UINT32 = 2**32
_WRAP = 1 << 24


class CsvFormatError(SessionError):
    """A CSV file is not a cfclient log file or is damaged."""


@dataclass
class CsvLog:
    """One log block read from a cfclient CSV.

    ``timestamps_s`` (n,) firmware time in seconds; ``values[var]`` (n,) float64 per variable
    ``group.name`` in header order; ``ctypes[var]`` the cflib type that holds the column
    losslessly (``int32_t`` for integer columns, ``double`` otherwise; the CSV has no types).
    """

    path: Path
    name: str
    timestamps_s: np.ndarray
    values: dict[str, np.ndarray] = field(default_factory=dict)
    ctypes: dict[str, str] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    """What was found damaged and done about it (a last line cut short, dropped)."""


def block_name_of(path: Path) -> str:
    """Block name from a cfclient file name: ``Motors-20240101T10-00-00.csv`` -> ``Motors``."""
    return _STAMP_SUFFIX.sub("", path.stem) or path.stem


def _parse(line: str, *, path: Path, lineno: int, width: int) -> list[float] | None:
    cells = line.strip().split(",")
    if len(cells) != width or not all(c.strip() for c in cells):
        return None  # a line cut short
    try:
        return [float(c) for c in cells]
    except ValueError:
        bad = next(c for c in cells if not _is_number(c))
        raise CsvFormatError(
            f"{path}: line {lineno} has the non-number {bad[:40]!r}; fix or delete that line"
        ) from None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def read_cfclient_csv(path: str | Path) -> CsvLog:
    """Read one cfclient log CSV (module docstring); one-line :class:`CsvFormatError` if bad."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")  # a BOM: Excel's save
    except OSError as exc:
        raise CsvFormatError(f"{path}: cannot read ({exc.strerror}); check the path") from None
    # (line number in the file, line): errors name the file's line, blank lines included
    lines = [(n, ln) for n, ln in enumerate(text.splitlines(), start=1) if ln.strip()]
    if not lines:
        raise CsvFormatError(f"{path}: empty file, not a cfclient log CSV")
    header = [h.strip() for h in lines[0][1].split(",")]
    if header[0] != "Timestamp" or len(header) < 2:
        raise CsvFormatError(
            f"{path}: not a cfclient log CSV (header starts {header[0][:30]!r}, "
            "expected 'Timestamp,<group.name>,...')"
        )
    variables = header[1:]
    try:
        check_variables(variables, where=f"{path}: header")
    except SessionError as exc:
        raise CsvFormatError(str(exc)) from None
    rows: list[list[float]] = []
    linenos: list[int] = []
    problems: list[str] = []
    for k, (i, line) in enumerate(lines[1:], start=2):
        row = _parse(line, path=path, lineno=i, width=len(header))
        if row is None:
            if k == len(lines) and len(line.split(",")) <= len(header):  # more is no cut
                problems.append(f"last line {i} is incomplete (client killed?); dropped")
                log.warning("%s: %s", path, problems[-1])
                break
            raise CsvFormatError(
                f"{path}: line {i} has {len(line.split(','))} columns (or empty ones), the "
                f"header {len(header)}; fix or delete that line"
            )
        rows.append(row)
        linenos.append(i)
    if not rows:  # one empty block need not keep the others of its flight out
        problems.append("header only, no samples (the block logged nothing); no stream")
        empty = np.zeros(0)
        return CsvLog(path=path, name=block_name_of(path), timestamps_s=empty,
                      values={v: empty for v in variables},
                      ctypes=dict.fromkeys(variables, "double"), problems=problems)
    data = np.array(rows, dtype=np.float64)  # (n, 1 + n_variables)
    bad = np.flatnonzero(~np.all(np.isfinite(data), axis=1))
    if len(bad):
        row = bad[0]
        col = header[int(np.flatnonzero(~np.isfinite(data[row]))[0])]
        raise CsvFormatError(f"{path}: line {linenos[row]} has a non-finite {col} "
                             f"({data[row][header.index(col)]:g}); fix or delete that line")
    stamps_ms = data[:, 0]
    if np.any(stamps_ms != np.round(stamps_ms)) or np.any(stamps_ms < 0) \
            or np.any(stamps_ms >= _UINT32):
        raise CsvFormatError(f"{path}: Timestamp must be whole milliseconds from 0 to "
                             f"{_UINT32 - 1} (the Crazyflie's tick)")
    values, ctypes = {}, {}
    for j, var in enumerate(variables, start=1):
        col = data[:, j]
        values[var] = col
        integral = bool(np.all(col == np.round(col)) and np.all(np.abs(col) < _INT32))
        ctypes[var] = "int32_t" if integral else "double"
    # cflib carries a 24-bit tick: undo its wrap-arounds so time never goes backwards
    wraps = np.concatenate([[0], np.cumsum(np.diff(stamps_ms) < -(_WRAP // 2))])
    stamps_ms = stamps_ms + wraps * _WRAP
    back = np.flatnonzero(np.diff(stamps_ms) < 0)
    if len(back):
        j = int(back[0]) + 1
        raise CsvFormatError(
            f"{path}: line {linenos[j]}: Timestamp {data[j, 0]:.0f} ms goes back from "
            f"{data[j - 1, 0]:.0f} ms on line {linenos[j - 1]}; the file is not one "
            "recording in time order (fix or delete those lines)")
    same = np.flatnonzero(np.diff(stamps_ms) == 0) + 1  # cflib stamps each packet anew
    if len(same):
        j = int(same[0])
        problems.append(f"{len(same)} row(s) repeat the Timestamp of the row before (first: "
                        f"line {linenos[j]}, {data[j, 0]:.0f} ms); kept, the later row's values "
                        "hold at that time")
        log.warning("%s: %s", path, problems[-1])
    return CsvLog(path=path, name=block_name_of(path), timestamps_s=stamps_ms / 1000.0,
                  values=values, ctypes=ctypes, problems=problems)
