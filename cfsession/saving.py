"""Where a closed session ends up: compressed in place, found where it was moved, written again
where it was deleted, or saved from memory after a failed write.

:class:`Settlement` is the last step of :meth:`cfsession.writer.SessionWriter.close`
(``docs/session-format.md``, "A folder moved or deleted while writing" and "When the disk
fills"): it checks that the writer's path still names the file it wrote and puts the session's
bytes where they belong. Every copy is written atomically: into a file created exclusively
(``O_EXCL``, random name) in the target's folder, written through that descriptor (through
:class:`~cfsession.diskfile.SessionFile`, so a disk that fills is an :class:`OSError`, never a
failing HDF5 file), ``fsync``-ed, then renamed onto the target; a planted symbolic link is never
followed.
"""

from __future__ import annotations

import contextlib
import errno
import io
import logging
import math
import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path

import h5py

from cfsession.diskfile import OPEN_FLAGS, SessionFile
from cfsession.errors import SessionError

__all__ = ["Settlement", "whereabouts"]

log = logging.getLogger("cfsession.writer")  # the writer's close: logged as the writer


class Settlement:
    """Settles a closed session written through ``sink`` (its descriptor still open) to
    ``path`` (see :meth:`cfsession.writer.SessionWriter.close`).

    :meth:`settle` returns where the session is; each thing that happened to it on the way is
    one line appended to ``notes`` (the writer's list). When only part of it could be kept,
    :attr:`saved_until` (``host_time``) and :attr:`path` (the file holding that part) are set
    before the one-line :class:`SessionError`.
    """

    def __init__(self, sink: SessionFile, path: Path, *, compress: bool, newest: float,
                 notes: list[str]) -> None:
        self.sink, self.path, self.compress = sink, path, compress
        self.newest = newest  # host_time of the newest row that reached the disk
        self.notes = notes
        self.saved_until: float | None = None
        self.mode = _mode_of(sink.fd)

    def settle(self, *, trouble: str, disk_full: bool) -> Path:
        """Where the closed session ends up; ``trouble``: the writer's, ``disk_full``: whether
        the disk or a quota refused room (no compressed copy is tried then)."""
        sink, original = self.sink, self.path
        current, gone = whereabouts(sink.fd, original)
        if current is not None and current != original:
            self.notes.append(f"{original} was moved while being written; the session is now "
                              f"{current}")
        if sink.memory is not None:  # a write failed: the whole file is in memory
            return self._save_from_memory(current or original, trouble=trouble, gone=gone)
        if current is None:  # the open file still holds it
            return self._write_again(original, gone=gone, source="the still open file")
        sink.close()  # Windows replaces no open file
        if self.compress and not disk_full:
            try:
                _repack(current)
            except Exception as exc:  # the uncompressed file is complete: never lose it
                log.debug("compressing %s", current, exc_info=True)
                log.warning("could not compress %s (%s); kept uncompressed", current,
                            _one_line(exc))
        elif self.compress:
            log.info("%s not compressed: the disk is full", current)
        return current

    def _write_again(self, original: Path, *, gone: str, source: str) -> Path:
        """The closed file's bytes to a new file at ``original`` (its folder made again, ``-2``
        ... if taken); one-line :class:`SessionError` if that fails."""
        try:
            target = _save_image(self.sink.image(), original, compress=self.compress,
                                 mode=self.mode)
        except Exception as exc:
            log.debug("writing %s again", original, exc_info=True)
            raise SessionError(f"{original} {gone}, and writing it again failed "
                               f"({_one_line(exc)}): the session is lost") from None
        self.notes.append(f"{original} {gone}; the session was written again, from {source}, "
                          f"to {target}")
        return target

    def _save_from_memory(self, target: Path, *, trouble: str, gone: str) -> Path:
        """After a failed write: the whole session from memory, compressed, to ``target``
        (replacing what reached the disk there, or a new file if it is gone)."""
        if gone:
            return self._write_again(target, gone=gone, source="memory")
        self.sink.close()  # Windows replaces no open file
        try:
            saved = _save_image(self.sink.image(), target, compress=True, mode=self.mode,
                                replace=True)
        except Exception as exc:
            log.debug("saving %s from memory", target, exc_info=True)
            if self.newest == -math.inf:
                raise SessionError(f"{trouble}; no row reached {target} (it holds the metadata "
                                   f"only) and saving the session at close failed too "
                                   f"({_one_line(exc)}): its data are lost") from None
            self.saved_until, self.path = self.newest, target
            raise SessionError(f"{target} holds the session up to "
                               f"{math.floor(self.newest * 10) / 10:.1f} s only "
                               f"({trouble}; saving the rest at close failed: "
                               f"{_one_line(exc)})") from None
        self.notes.append(f"{trouble}; the whole session, kept in memory since, was saved "
                          f"(compressed) to {saved} at close")
        return saved


def whereabouts(fd: int, path: Path) -> tuple[Path | None, str]:
    """The name of the file open as ``fd``: ``path``, or its new name when it (or its folder)
    was moved (from ``/proc/self/fd``); ``None`` and how it went when it has none to be
    found."""
    st = os.fstat(fd)
    if st.st_nlink == 0:
        return None, "was deleted while being written (its folder removed?)"

    def ours(p: Path) -> bool:
        try:
            cur = os.lstat(p)
        except (OSError, ValueError):
            return False
        return (cur.st_dev, cur.st_ino) == (st.st_dev, st.st_ino)

    unknown = "was moved while being written, to a place unknown"
    if ours(path):
        return path, ""
    try:
        name = Path(os.readlink(f"/proc/self/fd/{fd}"))
    except OSError:  # no /proc (not Linux)
        return None, unknown
    return (name, "") if ours(name) else (None, unknown)


def _one_line(exc: BaseException) -> str:
    """An exception as one short line (HDF5's messages span lines; an OSError's reason)."""
    text = " ".join(str(exc).split()) if str(exc).strip() else type(exc).__name__
    if isinstance(exc, OSError) and exc.strerror:
        text = exc.strerror
    return text[:200]


def _mode_of(fd: int) -> int:
    """Permission bits of the open file (the umask's, from its creation)."""
    try:
        return stat.S_IMODE(os.fstat(fd).st_mode) & 0o777
    except OSError:
        return 0o644


def _claim_new(path: Path) -> Path:
    """Create an empty file exclusively at ``path`` or the first free ``stem-N`` name."""
    path.parent.mkdir(parents=True, exist_ok=True)
    for n in range(1, 1001):
        candidate = path if n == 1 else path.with_name(f"{path.stem}-{n}{path.suffix}")
        try:
            os.close(os.open(candidate, os.O_CREAT | os.O_EXCL | os.O_WRONLY | OPEN_FLAGS,
                             0o600))
        except FileExistsError:
            continue
        return candidate
    raise FileExistsError(errno.EEXIST, f"{path} and 999 other names taken")


def _save_image(image: bytes, target: Path, *, compress: bool, mode: int,
                replace: bool = False) -> Path:
    """A closed session's bytes to ``target``: compressed (:func:`_copy_compressed`) or as they
    are, through a temporary file renamed onto ``target`` (over it with ``replace``, else onto a
    name claimed exclusively). Returns the name written."""
    if not replace:
        target = _claim_new(target)
    try:
        if compress:
            with h5py.File(io.BytesIO(image), "r") as src:
                tmp = _write_compressed(src, target, mode=mode)
        else:
            tmp = _write_tmp(target, mode=mode, fill=lambda fd: _write_all(fd, image))
        os.replace(tmp, target)
    except BaseException:
        if not replace:
            with contextlib.suppress(OSError):
                target.unlink()
        raise
    return target


def _write_all(fd: int, data: bytes) -> None:
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view):]


def _write_tmp(path: Path, *, mode: int, fill: Callable[[int], None]) -> Path:
    """A file created exclusively (``O_EXCL``, random name) beside ``path``, ``fill(fd)``-ed,
    ``fsync``-ed, with ``mode``; removed again if anything fails."""
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".repack")
    tmp = Path(tmp_name)
    try:
        try:
            if hasattr(os, "fchmod"):
                os.fchmod(fd, mode)
            else:  # Windows before Python 3.13
                os.chmod(tmp, mode)
            fill(fd)
            os.fsync(fd)
        finally:
            os.close(fd)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return tmp


def _write_compressed(src: h5py.File, path: Path, *, mode: int) -> Path:
    """``src`` compressed into a new temporary file beside ``path`` (:func:`_write_tmp`),
    through :class:`~cfsession.diskfile.SessionFile`: a disk that fills is an
    :class:`OSError`, never a failing HDF5 file."""

    def fill(fd: int) -> None:
        sink = SessionFile(fd)
        with h5py.File(sink, "w", libver="latest") as dst:
            _copy_compressed(src, dst)
        sink.raise_interrupt()
        if sink.failed is not None:
            raise sink.failed

    return _write_tmp(path, mode=mode, fill=fill)


def _repack(path: Path) -> None:
    """Rewrite ``path`` with gzip-compressed chunks, atomically: into a file created exclusively
    (``O_EXCL``, random name) in the same folder and written through that descriptor, so no
    name planted beforehand (a symlink) is ever followed; then renamed over ``path``, unless
    ``path`` has become a symlink meanwhile. The rewrite keeps ``path``'s permission bits (the
    umask's, from when it was created): ``mkstemp`` makes its file owner-only."""
    st = os.lstat(path)
    mode = stat.S_IMODE(st.st_mode) & 0o777 if stat.S_ISREG(st.st_mode) else 0o600
    with h5py.File(path, "r") as src:
        tmp = _write_compressed(src, path, mode=mode)
    try:
        if path.is_symlink():
            raise SessionError(f"{path}: became a symbolic link while closing; left as it is "
                               f"(the data are in {tmp})")
        os.replace(tmp, path)
    except BaseException:
        if tmp.exists() and not path.is_symlink():
            tmp.unlink()
        raise


def _copy_compressed(src: h5py.File, dst: h5py.File) -> None:
    """Every stream of ``src`` into ``dst`` with gzip-compressed chunks, attributes kept."""
    for key, value in src.attrs.items():
        dst.attrs[key] = value
    if isinstance(value := src.attrs.get("summary"), str):
        dst.attrs["summary"] = value.rstrip()
    for name, group in src.items():
        out = dst.create_group(name)
        for key, value in group.attrs.items():
            out.attrs[key] = value
        data = group["data"]
        ds = out.create_dataset(
            "data",
            data=data[()],
            maxshape=(None,),
            chunks=data.chunks,
            compression="gzip",
            compression_opts=4,
            shuffle=True,
            fillvalue=data.fillvalue,
        )
        for key, value in data.attrs.items():
            ds.attrs[key] = value
