"""The flight listener that records a session file (``docs/session-format.md``).

:class:`Recorder` implements :class:`groundstation.flight.FlightListener` on top of
:class:`cfsession.writer.SessionWriter`: ``begin`` creates the file with every stream,
``rows`` queues rows (the writer appends them at most ``flush_interval`` s apart, crash-safe),
``end`` stores the summary, marks the file closed cleanly and compresses it.

The file name is claimed when the file is created, by an exclusive create (``O_EXCL``): with
``unique=True`` a name another process took first (two flights started in the same second into
one folder) moves on to ``-2``, ``-3`` ...; an existing file is never written over.

A disk that fills (or a quota, or the file size limit) never makes ``rows`` raise: the writer
keeps :data:`~cfsession.writer.RESERVE_BYTES` allocated ahead, and the first
:attr:`~cfsession.writer.SessionWriter.trouble` goes to ``on_trouble`` (the runner's abort) once,
so the landing is still recorded. ``end`` never raises either: where the session ended up
(:attr:`Recorder.path`), what happened to it (:attr:`Recorder.notes`), whether it holds only part
of the flight (:attr:`Recorder.saved_until`) or was lost (:attr:`Recorder.error`) are for the
caller to report.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import re
import secrets
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from cfsession.schema import StreamSpec
from cfsession.writer import RESERVE_BYTES, SessionWriter, check_room
from groundstation.errors import SessionError

__all__ = ["Recorder", "check_folder", "check_tag", "session_path"]

log = logging.getLogger(__name__)

_MAX_SUFFIX = 1000


def _candidates(path: Path):
    """``path``, then ``stem-2.h5``, ``stem-3.h5`` ... (at most :data:`_MAX_SUFFIX`)."""
    yield path
    for n in range(2, _MAX_SUFFIX + 1):
        yield path.with_name(f"{path.stem}-{n}{path.suffix}")


def _os_error(path: Path, exc: OSError, *, option: str = "--out folder") -> SessionError:
    """A one-line error for a file that cannot be created."""
    if exc.errno == errno.ENAMETOOLONG:
        return SessionError(f"cannot create {path}: file name too long ({len(path.name)} "
                            "characters); give the plan a shorter name or choose a shorter "
                            f"{option}")
    return SessionError(f"cannot create {path}: {exc.strerror or exc}; choose another {option}")


def _claim(path: Path, *, unique: bool) -> Path:
    """Create an empty file exclusively at ``path`` (or, with ``unique``, the first free
    ``-N`` name) and return its path; one-line :class:`SessionError` when that is impossible."""
    for candidate in _candidates(path) if unique else (path,):
        try:
            fd = os.open(candidate, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            continue
        except OSError as exc:
            raise _os_error(candidate, exc) from None
        os.close(fd)
        return candidate
    raise SessionError(f"{path}: already exists; choose another output path" if not unique else
                       f"{path}: {_MAX_SUFFIX} sessions of that name exist; choose another "
                       "--out folder")


def check_folder(out: str | Path) -> Path:
    """Create the session folder ``out`` if missing and check that files can be created in
    it; one-line :class:`SessionError` otherwise."""
    from cfcommon.cli import names_a_file  # the command lines' rule (flying loads no click)

    folder = Path(out)
    if str(out) == "-":  # the usual name for standard output: not a folder anyone means
        raise SessionError("--out -: sessions are files in a folder, not a stream on standard "
                           "output; give a folder (its full path for one named '-')")
    if folder.exists() and not folder.is_dir():
        raise SessionError(f"{folder}: is a file, not a folder; choose another --out folder")
    if names_a_file(folder):
        parent = folder.parent if folder.parent != Path() else Path("sessions")
        raise SessionError(f"--out {folder}: names a session file, but --out is the folder the "
                           f"session files go in (named for you); give a folder, e.g. "
                           f"--out {parent}")
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SessionError(f"cannot create folder {folder}: {exc.strerror or exc}; choose "
                           "another --out folder") from None
    if not os.access(folder, os.W_OK | os.X_OK):
        raise SessionError(f"{folder}: not writable; choose another --out folder")
    return folder


_TAG = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,39}")


def check_tag(tag: str) -> str:
    """``tag`` if it can be part of a file name (letters, digits, ``.``, ``_``, ``-``, at most
    40, not starting with a punctuation mark); one-line :class:`SessionError` otherwise."""
    if tag and not _TAG.fullmatch(tag):
        raise SessionError(f"--name {tag!r}: use at most 40 letters, digits, '.', '_' or '-' "
                           "(starting with a letter or digit), e.g. --name validation")
    return tag


def session_path(*, out: str | Path, plan_name: str, tag: str = "") -> Path:
    """The first choice of file name, ``OUT/PLAN[-TAG]-YYYYmmddTHHMMSSZ.h5`` (UTC), checked before
    anything connects: the folder is created if missing, and a file of that name (or the next
    free ``-N``) is created, given the room a session starts with (twice
    :data:`~cfsession.writer.RESERVE_BYTES`) and removed again, so a read-only folder, a pseudo
    file system, an over-long name, a full disk or a file size limit (``ulimit -f``) too small
    is a one-line :class:`SessionError` now rather than after take-off. The name itself is
    claimed when :meth:`Recorder.begin` creates the file."""
    check_tag(tag)
    folder = check_folder(out)
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())  # UTC, as start_time_iso
    path = folder / "-".join([plan_name, *([tag] if tag else []), f"{stamp}.h5"])
    probe = _claim(path, unique=True)
    try:
        check_room(probe, 2 * RESERVE_BYTES)
    except BaseException as exc:
        _remove(probe)
        if isinstance(exc, OSError):
            raise _os_error(probe, exc) from None
        raise
    try:
        os.unlink(probe)
    except OSError as exc:
        raise _os_error(probe, exc) from None
    return path


class Recorder:
    """Writes every row the flight runner hands out to the session file ``path``.

    ``metadata`` may carry ``start_time_ns`` (wall clock at the session's time origin). With
    ``unique`` the file may end up as ``stem-2.h5`` ... when ``path`` is taken by the time it is
    created (``self.path`` is the file's name once :meth:`begin` returned); without it an
    existing ``path`` is a :class:`SessionError`.

    ``on_trouble(text)`` hears, once, that the disk (a quota, the file size limit) refuses the
    file more room or a write failed (one line; the runner aborts the flight on it, and the
    landing goes into the reserve); without it ``rows`` raises :class:`SessionError` then.
    After :meth:`end`: :attr:`path` is where the session is (another name if its folder was
    moved), :attr:`notes` what happened to it, :attr:`saved_until` the flight time the file
    holds rows up to when the rest could not be saved (``None``: all of it), :attr:`error`
    one line when it could not be saved at all.
    """

    def __init__(self, path: str | Path, *, flush_interval: float = 1.0,
                 compress_on_close: bool = True, unique: bool = False,
                 reserve: int | None = None) -> None:
        self.path = Path(path)
        self._flush_interval = flush_interval
        self._compress = compress_on_close
        self._unique = unique
        self._reserve = RESERVE_BYTES if reserve is None else reserve
        self._writer: SessionWriter | None = None
        self._flushed_at_s: float | None = None  # flight time of the last flight-time flush
        self._flushed_wall = 0.0
        self.on_trouble: Callable[[str], None] | None = None
        self.trouble = ""
        self.notes: list[str] = []
        self.saved_until: float | None = None
        self.error = ""

    def begin(self, *, streams: Sequence[StreamSpec], metadata: Mapping[str, Any]) -> None:
        """Create the file: claim its name exclusively, write it under a temporary name in the
        same folder and rename it onto the claimed (empty) file. One-line
        :class:`SessionError` when it cannot be created."""
        meta = dict(metadata)
        start_ns = meta.pop("start_time_ns", None)
        path = _claim(self.path, unique=self._unique)
        tmp = path.with_name(f".gs-{os.getpid()}-{secrets.token_hex(4)}.h5.part")
        try:
            writer = SessionWriter(tmp, streams=streams, metadata=meta,
                                   start_time_ns=start_ns, flush_interval=self._flush_interval,
                                   compress_on_close=self._compress, reserve=self._reserve)
        except OSError as exc:
            _remove(path, tmp)
            raise _os_error(path, exc) from None
        except BaseException:
            _remove(path, tmp)
            raise
        try:
            os.replace(tmp, path)  # onto our own placeholder: nobody else's file
        except OSError as exc:
            writer.close()
            _remove(path, tmp)
            raise _os_error(path, exc) from None
        writer.path = path
        self.path, self._writer = path, writer

    def rows(self, stream: str, rows: Sequence[tuple]) -> None:
        if self._writer is None:
            raise RuntimeError("Recorder.rows() before begin()")
        self._writer.extend(stream, rows)
        self._flush_on_flight_time(rows)
        if self._writer.trouble and not self.trouble:
            self.trouble = self._writer.trouble
            if self.on_trouble is None:
                raise SessionError(self.trouble)
            self.on_trouble(self.trouble)

    def _flush_on_flight_time(self, rows: Sequence[tuple]) -> None:
        """Flush every ``flush_interval`` of *flight* time too (the writer flushes on wall
        time): a simulated flight at 20x fits a whole hover in one wall second, and a crash
        then must not lose it. At most every 0.1 s of wall time."""
        if not rows:
            return
        try:
            t0, t = float(rows[0][0]), float(rows[-1][0])
        except (TypeError, ValueError, IndexError):
            return
        if self._flushed_at_s is None:
            self._flushed_at_s = t0  # the flight's first row
        now = time.monotonic()
        if t - self._flushed_at_s >= self._flush_interval and now - self._flushed_wall >= 0.1:
            self._writer.flush()
            self._flushed_at_s, self._flushed_wall = t, now

    def counts(self) -> dict[str, int]:
        """Rows per stream so far (written plus buffered)."""
        return {} if self._writer is None else self._writer.counts()

    def end(self, *, summary: Mapping[str, Any]) -> None:
        """Close the session (see the class for what it tells afterwards); never raises."""
        writer = self._writer
        if writer is None or writer.closed:
            return
        duration = summary.get("duration_s")
        try:
            self.path = writer.close(duration_s=None if duration is None else float(duration),
                                     summary=summary)
        except SessionError as exc:
            if writer.saved_until is None:
                self.error = str(exc)
            else:  # the file holds the flight up to then: the caller says so in its words
                log.warning("%s", exc)
            self.path = writer.path
        except Exception as exc:  # unforeseen: one line here, the details at debug level
            log.debug("closing %s", self.path, exc_info=True)
            self.error = (f"closing {self.path} failed ({type(exc).__name__}: "
                          f"{' '.join(str(exc).split())[:200]})")
        self.notes, self.saved_until = list(writer.notes), writer.saved_until
        self.trouble = self.trouble or writer.trouble
        if not self.error:
            log.info("session written: %s", self.path)


def _remove(*paths: Path) -> None:
    for p in paths:
        with contextlib.suppress(OSError):
            p.unlink()
