"""Locate keys of a TOML document by line, and read its tables with typed, closed schemas.

:mod:`tomllib` parses TOML but reports no positions. :func:`key_lines` scans the (already valid)
text once and maps every key path, e.g. ``("phase", 2, "roll", "amplitude")`` for the
``amplitude`` key of the third ``[[phase]]``'s ``roll`` table, to its 1-based line; it follows
``[table]`` and ``[[array]]`` headers, dotted keys, inline tables, and skips multi-line arrays
and strings. :class:`TomlTable` refuses unknown keys (with a "did you mean" hint), wrong types,
non-finite numbers (TOML ``nan``, ``inf``; they compare false with every limit) and out-of-range
numbers, each as a one-line :class:`~groundstation.errors.PlanError` that reads
``FILE:LINE: key.path: problem; what to change``. :func:`set_keys` edits values through
:mod:`tomlkit`, which keeps every comment and all layout of the values it does not change.
"""

from __future__ import annotations

import difflib
import math
import re
import reprlib
from collections.abc import Iterable, Sequence
from typing import Any

import tomlkit
from tomlkit.container import Container
from tomlkit.items import Array, InlineTable

from groundstation.errors import PlanError

__all__ = ["REQUIRED", "TomlSource", "TomlTable", "comment_text", "did_you_mean", "dotted",
           "key_lines", "set_keys", "shown"]

_KEY = r"""(?:[A-Za-z0-9_-]+|"(?:[^"\\]|\\.)*"|'[^']*')"""
_DOTTED = re.compile(rf"\s*({_KEY}(?:\s*\.\s*{_KEY})*)\s*")
_INLINE_KEY = re.compile(rf"[{{,]\s*({_KEY}(?:\s*\.\s*{_KEY})*)\s*=")


def _parts(dotted: str) -> list[str]:
    return [p.strip("\"'") for p in re.findall(_KEY, dotted)]


def _value_end(lines: list[str], row: int, col: int) -> int:
    """Index of the last line of the value starting at ``lines[row][col]`` (arrays, strings)."""
    depth, quote = 0, None
    while row < len(lines):
        line, pos = lines[row], col
        while pos < len(line):
            if quote:  # inside a multi-line string
                if line.startswith(quote, pos):
                    pos, quote = pos + 3, None
                else:
                    pos += 2 if quote == '"""' and line[pos] == "\\" else 1
                continue
            c = line[pos]
            if line.startswith(('"""', "'''"), pos):
                quote, pos = line[pos : pos + 3], pos + 3
                continue
            if c == "#":
                break
            if c in "\"'":
                pos += 1
                while pos < len(line) and line[pos] != c:
                    pos += 2 if c == '"' and line[pos] == "\\" else 1
            depth += (c in "[{") - (c in "]}")
            pos += 1
        if depth <= 0 and quote is None:
            return row
        row, col = row + 1, 0
    return len(lines) - 1


def key_lines(text: str) -> dict[tuple, int]:
    """Map key paths such as ``("phase", 2, "roll", "amplitude")`` to 1-based line numbers."""
    lines = text.splitlines()
    where: dict[tuple, int] = {}
    arrays: dict[tuple, int] = {}  # resolved path of an array of tables -> its last index
    current: tuple = ()
    row = 0
    while row < len(lines):
        stripped = lines[row].lstrip()
        if stripped.startswith("["):
            double = stripped.startswith("[[")
            match = _DOTTED.match(stripped, 2 if double else 1)
            path: tuple = ()
            for part in _parts(match.group(1)) if match else []:
                path += (part,)
                if path in arrays and not (double and len(path) == len(_parts(match.group(1)))):
                    path += (arrays[path],)
            if double:
                arrays[path] = arrays.get(path, -1) + 1
                path += (arrays[path],)
            current = path
            for k in range(1, len(path) + 1):
                where.setdefault(path[:k], row + 1)
        elif stripped and not stripped.startswith("#"):
            match = _DOTTED.match(lines[row])
            if match and lines[row][match.end() : match.end() + 1] == "=":
                path = current + tuple(_parts(match.group(1)))
                for k in range(len(current) + 1, len(path) + 1):
                    where.setdefault(path[:k], row + 1)
                end = _value_end(lines, row, match.end() + 1)
                value = lines[row][match.end() + 1 :].lstrip()
                if value.startswith("{"):
                    for inner in _INLINE_KEY.finditer(value):
                        where.setdefault(path + tuple(_parts(inner.group(1))), row + 1)
                row = end
        row += 1
    return where


def _children(node: Any, part: str | int) -> list[Any]:
    """The items at ``part`` of a table, array of tables or array: every table of a key written
    in dotted form (``roll.signal = ...``, ``roll.seed = ...``)."""
    if isinstance(part, int):
        return [node[part]] if 0 <= part < len(node) else []
    body = node.body if isinstance(node, Container) else node.value.body
    return [item for key, item in body if key is not None and key.key == part]


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """``did you mean 'x'? `` for the one of ``known`` closest to ``name`` (a typo of a key, a
    choice or a plan's name), ``""`` when none is close. Case is ignored (``"PRBS"`` finds
    ``prbs`` and says that case matters)."""
    by_lower: dict[str, str] = {}
    for k in sorted(known):
        by_lower.setdefault(k.lower(), k)
    near = difflib.get_close_matches(name.lower(), list(by_lower), n=1, cutoff=0.5)
    if not near:
        return ""
    match = by_lower[near[0]]
    case = ", case matters" if name.lower() == match.lower() else ""
    return f"did you mean '{match}'{case}? "


_NOT_IN_COMMENTS = re.compile("[\x00-\x08\x0a-\x1f\x7f]")
"""What a TOML comment may not hold: control characters other than tab (TOML 1.0)."""


def comment_text(text: str) -> str:
    """``text`` as one TOML comment may hold it: control characters (a line feed in a file
    name that would end the comment and start a key) written as Python escapes (``\\n``)."""
    return _NOT_IN_COMMENTS.sub(lambda m: repr(m.group())[1:-1], text)


def set_keys(text: str, *, edits: Sequence[tuple[tuple, Any, str]], mark: str = "#") -> str:
    """``text`` with each ``(path, value, note)`` applied by :mod:`tomlkit`: the key at ``path``
    (as :func:`key_lines`'s) set to ``value``, or added to its table when absent, and a ``note``
    (if any) made its line's trailing comment ``MARK NOTE`` (:func:`comment_text`); comments
    keep their column. Keys of an inline table share its line: ``MARK key: note; key: note``.
    Everything not edited stays byte for byte; no edits give ``text`` back."""
    doc = tomlkit.parse(text)
    notes: dict[Any, tuple[Any, int, list[str]]] = {}  # line -> its item, old width, notes
    for path, value, note in edits:
        *parent, key = path
        tables, line = [doc], None  # line: the inline table or array the key is written in
        for k, part in enumerate(parent):
            tables = [c for t in tables for c in _children(t, part)]
            if not tables:
                raise PlanError(f"no table {dotted(tuple(parent[: k + 1]))} to set {key} in")
            if line is None and isinstance(tables[-1], InlineTable | Array):
                line = tables[-1]
                notes.setdefault(id(line), (line, len(line.as_string()), []))
        holder = next((t for t in tables if key in t), tables[-1])
        table = holder if isinstance(holder, Container) else holder.value
        width = len(table.item(key).as_string()) if key in holder else 0
        holder[key] = value  # tomlkit keeps the old item's indent and comment
        if line is not None:
            notes[id(line)][2].extend([f"{key}: {note}"] if note else [])
        else:
            item = table.item(key)
            notes[tuple(path)] = (item, width or len(item.as_string()), [note] if note else [])
    for item, width, texts in notes.values():  # comments at their column
        had = bool(item.trivia.comment)
        if had or texts:
            pad = len(item.trivia.comment_ws) + width - len(item.as_string()) if had else 2
            if texts:
                item.comment(comment_text(f"{mark} {'; '.join(texts)}"))
            item.trivia.comment_ws = " " * max(2 if texts else 1, pad)
    return doc.as_string()


def ensure_tables(text: str, *, path: tuple[str, ...]) -> str:
    """``text`` with the tables of ``path`` (e.g. ``("parameters", "pid_attitude")``) added
    where missing, at the end of the file (what :func:`set_keys` needs to add a key there);
    ``text`` itself when they all exist."""
    doc = tomlkit.parse(text)
    table: Any = doc
    changed = False
    for k, part in enumerate(path):
        if part not in table:
            table[part] = tomlkit.table(is_super_table=k < len(path) - 1)
            changed = True
        table = table[part]
    return doc.as_string() if changed else text


_SHOWN = reprlib.Repr()
_SHOWN.maxstring = _SHOWN.maxother = _SHOWN.maxlong = 60
_SHOWN.maxlevel, _SHOWN.maxlist, _SHOWN.maxdict = 2, 4, 4


def shown(value: Any) -> str:
    """``value`` as an error message quotes it: its repr (line breaks and other unprintable
    characters escaped), cut to about 60 characters and 2 levels of nesting, so a plan's long,
    deep or multi-line value keeps the error on one short line."""
    return _SHOWN.repr(value)


_BARE = re.compile(r"[A-Za-z0-9_-]{1,64}")


def dotted(path: tuple) -> str:
    """``phase[2].roll.amplitude``; a key TOML must quote (or a very long one) as :func:`shown`
    quotes it, so a key with a line break keeps the error on one line."""
    return "".join(
        f"[{p}]" if isinstance(p, int) else f".{p}" if _BARE.fullmatch(p) else f".{shown(p)}"
        for p in path
    ).lstrip(".")


REQUIRED = object()
_INT64 = (-(1 << 63), (1 << 63) - 1)
_KINDS = {
    float: "a number",
    int: "an integer",
    str: "a string",
    dict: "a table",
    list: "an array of tables",
}


def _unit(unit: str) -> str:
    """`` (states)``, `` (deg)``: the unit a number key is given in, for its error."""
    return f" ({unit})" if unit else ""


class TomlSource:
    """The plan text, its key lines, and the one way to build an error that points into it."""

    def __init__(self, *, text: str, source: str) -> None:
        self.source = source
        self.lines = key_lines(text)

    def line(self, path: tuple) -> int | None:
        for k in range(len(path), 0, -1):
            if path[:k] in self.lines:
                return self.lines[path[:k]]
        return None

    def error(self, path: tuple, message: str) -> PlanError:
        return PlanError(self.note(path, message))

    def note(self, path: tuple, message: str) -> str:
        """``FILE:LINE: key.path: message``, as an error or a warning names the key."""
        line = self.line(path)
        where = f"{self.source}:{line}" if line else self.source
        return f"{where}: {dotted(path)}: {message}"

    def ref(self, path: tuple) -> str:
        """``vehicle.max_roll_deg (line 9)``: how a message names a second key."""
        line = self.line(path)
        return dotted(path) + (f" (line {line})" if line else "")


class TomlTable:
    """A TOML table: :meth:`allow` closes its key set; typed getters raise errors naming key and
    line."""

    def __init__(self, src: TomlSource, path: tuple, data: Any) -> None:
        if not isinstance(data, dict):
            raise src.error(path, f"must be a table, got {type(data).__name__} {shown(data)}")
        self.src, self.path, self.data = src, path, data

    def allow(self, allowed: set[str]) -> TomlTable:
        """Refuse any key outside ``allowed`` (typos must not pass silently); returns self."""
        for key in self.data:
            if key not in allowed:
                names = ", ".join(sorted(allowed))
                raise self.src.error((*self.path, key), f"unknown key {shown(key)}; "
                                     f"{did_you_mean(key, allowed)}allowed keys: {names}")
        return self

    def pwm(self, key: str, *, default: Any = REQUIRED) -> int:
        """A thrust command in PWM units, an integer 0-65535."""
        return self.number(key, lo=0, hi=65535, unit="PWM", kind=int, default=default)

    def get(self, key: str, kind: type, *, default: Any = REQUIRED, unit: str = "") -> Any:
        path = (*self.path, key)
        if key not in self.data:
            if default is REQUIRED:
                raise self.src.error(path, f"missing required key '{key}' ({_KINDS[kind]})")
            return default
        value = self.data[key]
        numeric = isinstance(value, int | float) and not isinstance(value, bool)
        if numeric and isinstance(value, int) and not _INT64[0] <= value <= _INT64[1]:
            # TOML's integers are 64-bit, tomllib reads any size: float() of 10**400 overflows
            raise self.src.error(path, f"{shown(value)} is beyond TOML's 64-bit integers; use "
                                 f"{_KINDS.get(kind, 'a value')} in range{_unit(unit)}")
        if kind in (float, int) and numeric and not math.isfinite(value):
            # TOML's nan/inf compare false with every limit: refuse them before any range check
            want = "a finite number" if kind is float else "an integer"
            raise self.src.error(
                path, f"{value!r} is not a finite number; use {want}{_unit(unit)}")
        if kind is float and numeric:
            return float(value)
        if kind is int and numeric and float(value).is_integer():
            return int(value)
        if kind in (str, dict, list) and isinstance(value, kind):
            return value
        raise self.src.error(path, f"{shown(value)} is not {_KINDS[kind]}{_unit(unit)}")

    def number(
        self,
        key: str,
        *,
        lo: float,
        hi: float,
        unit: str,
        default: Any = REQUIRED,
        kind: type = float,
        lo_open: bool = False,
    ) -> Any:
        """A number within ``[lo, hi]`` (``(lo, hi]`` if ``lo_open``), refused otherwise."""
        value = self.get(key, kind, default=default, unit=unit)
        if value is None:
            return value
        inside = lo < value <= hi if lo_open else lo <= value <= hi  # False for nan, too
        if not inside:
            low = f"> {lo:g}" if lo_open else f">= {lo:g}"
            raise self.src.error(
                (*self.path, key),
                f"{value:g} {unit} is out of range; use a value {low} and <= {hi:g} {unit}",
            )
        return value

    def choice(self, key: str, options: tuple[str, ...], *, default: Any = REQUIRED) -> str:
        value = self.get(key, str, default=default)
        if value not in options:
            hint = did_you_mean(value, options).rstrip()
            raise self.src.error((*self.path, key), f"{shown(value)} is not one of "
                                 f"{list(options)}{'; ' + hint if hint else ''}")
        return value

    def ticks(
        self,
        key: str,
        *,
        rate_hz: float,
        default: Any = REQUIRED,
        lo: float = 0.0,
        hi: float = 3600.0,
        lo_open: bool = True,
    ) -> int:
        """A time in s that must be a whole number of setpoint periods; returned in ticks."""
        seconds = self.number(key, lo=lo, hi=hi, unit="s", default=default, lo_open=lo_open)
        exact = seconds * rate_hz
        ticks = round(exact)
        if abs(ticks - exact) > 1e-6:
            raise self.src.error(
                (*self.path, key),
                f"{seconds:g} s is not a whole number of setpoint periods "
                f"({1 / rate_hz:g} s at {rate_hz:g} Hz); use "
                f"{math.floor(exact) / rate_hz:g} or {math.ceil(exact) / rate_hz:g} s",
            )
        if lo_open and ticks <= lo * rate_hz:  # 5e-324 s: within 1e-6 of 0 ticks, no phase
            least = (math.floor(lo * rate_hz) + 1) / rate_hz
            raise self.src.error(
                (*self.path, key),
                f"{seconds:g} s rounds to {ticks} setpoint periods ({1 / rate_hz:g} s at "
                f"{rate_hz:g} Hz each); use {least:g} s or more",
            )
        return ticks
