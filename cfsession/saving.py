"""Where a closed session ends up: compressed in place, found where it was moved, written again
where it was deleted, or saved from memory after a failed write.

:class:`Settlement` is the last step of :meth:`cfsession.writer.SessionWriter.close`
(``docs/session-format.md``, "A folder moved or deleted while writing" and "When the disk
fills"): it checks that the writer's path still names the file it wrote and puts the session's
bytes where they belong. Every copy is compressed in memory, then written atomically
(:mod:`cfsession.copies`): into a file created exclusively (``O_EXCL``, random name) in the
target's folder, ``fsync``-ed, renamed onto the target; a planted symbolic link is never
followed. Two fall-backs keep a session that would otherwise be lost: saved from memory with no
room for a second copy, it is written over the partial file in place if it fits there; written
again with its folder impossible to make again (a file took its name), it goes to the nearest
folder that takes it (:func:`fallbacks`).
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path

from cfsession.copies import (
    WriteBackFailed,
    compressed_image,
    overwrite_in_place,
    repack,
    save_image,
)
from cfsession.diskfile import SessionFile
from cfsession.errors import SessionError

__all__ = ["Settlement", "fallbacks", "whereabouts"]

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

    def settle(self, *, trouble: str) -> Path:
        """Where the closed session ends up; ``trouble``: the writer's."""
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
        if self.compress:
            try:
                skipped = repack(current)
            except Exception as exc:  # the uncompressed file is complete: never lose it
                log.debug("compressing %s", current, exc_info=True)
                log.warning("could not compress %s (%s); kept uncompressed", current,
                            _one_line(exc))
            else:
                if skipped:
                    log.info("%s not compressed: %s", current, skipped)
        return current

    def _write_again(self, original: Path, *, gone: str, source: str) -> Path:
        """The closed file's bytes to a new file at ``original`` (its folder made again, ``-2``
        ... if taken), else in the nearest folder that takes it (:func:`fallbacks`); one-line
        :class:`SessionError` if none does."""
        try:
            image = self.sink.image()
            data = compressed_image(image) if self.compress else image
        except Exception as exc:
            log.debug("reading %s back", original, exc_info=True)
            raise SessionError(f"{original} {gone}, and writing it again failed "
                               f"({_one_line(exc)}): the session is lost") from None
        first: Exception | None = None
        for folder in _own_then_fallbacks(original):  # the fallbacks only once it failed
            try:
                target = save_image(data, folder / original.name, mode=self.mode)
            except Exception as exc:
                log.debug("writing %s again in %s", original, folder, exc_info=True)
                first = first or exc
                continue
            if first is None:
                self.notes.append(f"{original} {gone}; the session was written again, from "
                                  f"{source}, to {target}")
            else:
                self.notes.append(f"{original} {gone}, and writing it again there failed "
                                  f"({_one_line(first)}); the session was written, from "
                                  f"{source}, to {target} instead")
            return target
        raise SessionError(f"{original} {gone}, and writing it again failed "
                           f"({_one_line(first)}), here or in another folder: the session is "
                           f"lost") from None

    def _save_from_memory(self, target: Path, *, trouble: str, gone: str) -> Path:
        """After a failed write: the whole session from memory, compressed, to ``target``
        (replacing what reached the disk there, through a copy beside it or, with no room for
        one, over it in place; or a new file if it is gone)."""
        if gone:
            return self._write_again(target, gone=gone, source="memory")
        ids = _ids_of(self.sink.fd)
        self.sink.close()  # Windows replaces no open file
        how = "(compressed)"
        try:
            data = compressed_image(self.sink.image())
            try:
                saved = save_image(data, target, mode=self.mode, replace=True)
            except OSError as exc:  # no room for a second copy: over the partial file
                log.debug("saving %s from memory beside it", target, exc_info=True)
                if ids is None:
                    raise
                try:
                    overwrite_in_place(target, data, ids=ids)
                except WriteBackFailed as again:  # the partial file is damaged: never claim it
                    log.debug("writing %s back", target, exc_info=True)
                    raise SessionError(
                        f"{trouble}; saving the session at close failed ({_one_line(exc)}; "
                        f"over the partial file: {again.reason[:200]}) and writing the partial "
                        f"file back failed too ({again.back[:200]}): {target} is damaged, its "
                        f"data are lost") from None
                except OSError as again:
                    raise OSError(again.errno, f"{_one_line(exc)}; over the partial file: "
                                               f"{_one_line(again)}") from None
                saved, how = target, (f"(compressed, {len(data) >> 10} KiB) over the partial "
                                      f"file, no room being left for a copy beside it,")
        except SessionError:
            raise
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
                          f"{how} to {saved} at close")
        return saved


def _own_then_fallbacks(original: Path) -> Iterator[Path]:
    """``original``'s folder, then (computed only if that one failed) :func:`fallbacks`."""
    yield original.parent
    try:
        more = fallbacks(original)
    except Exception:  # never let looking for another folder lose the session
        log.debug("finding folders for %s", original, exc_info=True)
        more = [Path(tempfile.gettempdir())]
    yield from more


def fallbacks(original: Path) -> list[Path]:
    """Folders to put a session in when its own (``original``'s) cannot be made again, in
    order: the nearest existing folder above it, the current folder (if it still exists), the
    temporary folder (``tempfile.gettempdir()``); each only if writable, never the file
    system's root, nor ``original``'s own folder."""
    found: list[Path] = []
    for parent in original.parent.parents:
        if _is_dir(parent):
            found.append(parent)
            break
    with contextlib.suppress(OSError):  # the current folder deleted: none
        found.append(Path.cwd())
    found = [f for f in found if _below_root(f)]
    found.append(Path(tempfile.gettempdir()))
    out: list[Path] = []
    for folder in found:
        if (os.access(folder, os.W_OK | os.X_OK) and not _same(folder, original.parent)
                and not any(_same(folder, f) for f in out)):
            out.append(folder)
    return out


def _is_dir(p: Path) -> bool:
    try:
        return p.is_dir()
    except OSError:  # no permission to look
        return False


def _below_root(p: Path) -> bool:
    """``p`` is not the file system's root (``/``, a Windows drive's); False when that cannot
    be told (relative, with the current folder deleted)."""
    try:
        p = p.absolute()
    except OSError:
        return False
    return p.parent != p


def _same(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def _ids_of(fd: int) -> tuple[int, int] | None:
    try:
        st = os.fstat(fd)
    except OSError:
        return None
    return st.st_dev, st.st_ino


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


