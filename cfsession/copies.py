"""Copies of a closed session written at close: compressed in memory, then put on the disk
atomically (a file created exclusively beside the target, ``fsync``-ed, renamed onto it) or, when
there is no room for a second copy, over the partial file in place.

Used by :class:`cfsession.saving.Settlement` (``docs/session-format.md``, "When the disk
fills" and "A folder moved or deleted while writing"). A planted symbolic link is never
followed: every file is opened with :data:`~cfsession.diskfile.OPEN_FLAGS` or created with
``O_EXCL``.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import stat
import tempfile
from pathlib import Path

import h5py
import numpy as np

from cfsession.diskfile import OPEN_FLAGS, read_all, write_all
from cfsession.errors import SessionError

__all__ = ["WriteBackFailed", "claim_new", "compressed_image", "free_bytes",
           "overwrite_in_place", "renamed", "repack", "save_image"]

ROOM_SLACK = 64 << 10
"""Free space beyond a copy's size that :func:`repack` wants before it tries (a file system's
own metadata, the folder entry)."""


def free_bytes(folder: Path) -> int | None:
    """Bytes an unprivileged process may still write in ``folder`` (``statvfs``); ``None`` when
    unknown (no ``statvfs``: Windows)."""
    if not hasattr(os, "statvfs"):
        return None
    try:
        st = os.statvfs(folder)
    except OSError:
        return None
    return st.f_bavail * st.f_frsize


def compressed_image(image: bytes) -> bytes:
    """A closed session's bytes rewritten with gzip-compressed chunks, in memory."""
    out = io.BytesIO()
    with h5py.File(io.BytesIO(image), "r") as src, \
            h5py.File(out, "w", libver="latest", rdcc_nbytes=0) as dst:  # rows in write order
        _copy_compressed(src, dst)
    return out.getvalue()


def renamed(image: bytes, name: str) -> bytes:
    """``image`` with its stored summary's ``file`` (the file's name) set to ``name``; the same
    bytes when it has no such entry or already names ``name``."""
    with h5py.File(io.BytesIO(image), "r") as f:
        summary = _summary_of(f)
    if summary is None or summary.get("file") in (None, name):
        return image
    buf = io.BytesIO(image)
    with h5py.File(buf, "r+") as f:
        summary["file"] = name
        f.attrs["summary"] = json.dumps(summary, sort_keys=True, default=str)
    return buf.getvalue()


def _summary_of(f: h5py.File) -> dict | None:
    value = f.attrs.get("summary")
    if isinstance(value, bytes):
        value = value.decode("utf-8", errors="replace")
    try:
        summary = json.loads(value) if isinstance(value, str) and value.strip() else None
    except ValueError:
        return None
    return summary if isinstance(summary, dict) else None


def claim_new(path: Path) -> Path:
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


def save_image(data: bytes, target: Path, *, mode: int, replace: bool = False) -> Path:
    """``data`` (a session's final bytes) to ``target`` through a temporary file renamed onto it
    (over it with ``replace``, else onto a name claimed exclusively, whose summary is made to
    name it: :func:`renamed`). Returns the name written."""
    if not replace:
        target = claim_new(target)
    try:
        data = renamed(data, target.name)
        tmp = _write_tmp(target, mode=mode, data=data)
        os.replace(tmp, target)
    except BaseException:
        if not replace:
            with contextlib.suppress(OSError):
                target.unlink()
        raise
    return target


class WriteBackFailed(OSError):
    """Writing over a file in place failed (``reason``), and so did writing its old contents
    back (``back``): the file is damaged."""

    def __init__(self, code: int, reason: str, back: str) -> None:
        super().__init__(code, f"{reason}; writing the partial file back failed too ({back}): "
                               f"the file is damaged")
        self.reason, self.back = reason, back


def overwrite_in_place(path: Path, data: bytes, *, ids: tuple[int, int]) -> None:
    """``data`` over the file ``path`` (it must still be the file ``ids``, ``(st_dev,
    st_ino)``), ``fsync``-ed. For when there is no room for a copy
    beside it: ``data`` must fit in the room the file holds plus what is free. It is written
    over the file's first bytes (room already held: a file system that does not copy on write
    needs none more), ``fsync``-ed, then the rest cut off and ``fsync``-ed again. If writing
    fails after changing any byte, what the file held is written back before the error is
    raised; if that fails too, :class:`WriteBackFailed` (the file is damaged). Not atomic: a
    process killed (or power lost) while ``data`` is being written leaves neither the old
    contents nor the new."""
    fd = os.open(path, os.O_RDWR | OPEN_FLAGS)
    try:
        st = os.fstat(fd)
        if (st.st_dev, st.st_ino) != ids or not stat.S_ISREG(st.st_mode):
            raise OSError(errno.ESTALE, f"{path} is no longer the session's file")
        held = getattr(st, "st_blocks", 0) * 512 or st.st_size
        room = held + (free_bytes(path.parent) or 0)
        if len(data) > room:
            raise OSError(errno.ENOSPC, f"the compressed session ({len(data) >> 10} KiB) does "
                                        f"not fit in the {room >> 10} KiB there are")
        before = read_all(fd, st.st_size)
        written = [0]
        try:
            _put(fd, data, written)
        except BaseException as exc:
            if not written[0]:  # not a byte changed: the file is as it was
                raise
            try:
                _put(fd, before)
            except OSError as back:
                reason = (exc.strerror if isinstance(exc, OSError) and exc.strerror
                          else str(exc) or type(exc).__name__)
                raise WriteBackFailed(getattr(exc, "errno", None) or errno.EIO, reason,
                                      back.strerror or str(back)) from exc
            raise
    finally:
        os.close(fd)


def _put(fd: int, data: bytes, written: list[int] | None = None) -> None:
    """``data`` over the file from its start (into the room it holds: no new room needed for
    what fits in its size), ``fsync``-ed, then the rest cut off and ``fsync``-ed again (the new
    bytes are on the disk before the old ones beyond them go). ``written[0]``: how many bytes
    of ``data`` were written, as it goes."""
    write_all(fd, data, written=written)
    os.fsync(fd)
    os.ftruncate(fd, len(data))
    os.fsync(fd)


def _write_tmp(path: Path, *, mode: int, data: bytes) -> Path:
    """A file created exclusively (``O_EXCL``, random name) beside ``path`` holding ``data``,
    ``fsync``-ed, with ``mode``; removed again if anything fails."""
    fd, tmp_name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".repack")
    tmp = Path(tmp_name)
    try:
        try:
            if hasattr(os, "fchmod"):
                os.fchmod(fd, mode)
            else:  # Windows before Python 3.13
                os.chmod(tmp, mode)
            write_all(fd, data)
            os.fsync(fd)
        finally:
            os.close(fd)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    return tmp


def repack(path: Path) -> str:
    """Rewrite ``path`` with gzip-compressed chunks, atomically: compressed in memory, written
    into a file created exclusively (``O_EXCL``, random name) in the same folder, then renamed
    over ``path``, unless ``path`` has become a symlink meanwhile. The rewrite keeps ``path``'s
    permission bits (the umask's, from when it was created): ``mkstemp`` makes its file
    owner-only. Returns ``""``, or why it was not tried: the free space (``statvfs``) does not
    hold the compressed copy."""
    st = os.lstat(path)
    mode = stat.S_IMODE(st.st_mode) & 0o777 if stat.S_ISREG(st.st_mode) else 0o600
    fd = os.open(path, os.O_RDONLY | OPEN_FLAGS)
    try:
        data = compressed_image(read_all(fd, os.fstat(fd).st_size))
    finally:
        os.close(fd)
    free = free_bytes(path.parent)
    if free is not None and free < len(data) + ROOM_SLACK:
        return (f"the disk is full ({free >> 10} KiB free, the compressed copy needs "
                f"{(len(data) + ROOM_SLACK) >> 10} KiB)")
    tmp = _write_tmp(path, mode=mode, data=data)
    try:
        if path.is_symlink():
            raise SessionError(f"{path}: became a symbolic link while closing; left as it is "
                               f"(the data are in {tmp})")
        os.replace(tmp, path)
    except BaseException:
        if tmp.exists() and not path.is_symlink():
            tmp.unlink()
        raise
    return ""


def _copy_compressed(src: h5py.File, dst: h5py.File) -> None:
    """Every stream of ``src`` into ``dst`` with gzip-compressed chunks, attributes kept.

    Laid out for a copy cut short (``docs/session-format.md``, "Damaged files"): every group,
    attribute and dataset is created before any row is written, each non-empty dataset with its
    final size (so its chunk index is a fixed array, allocated at once), so the metadata lies at
    the start and the rows after it: a file losing its last 1 % loses about that share of rows,
    where links and chunk indices written last lost every stream."""
    for key, value in src.attrs.items():
        dst.attrs[key] = value
    if isinstance(value := src.attrs.get("summary"), str):
        dst.attrs["summary"] = value.rstrip()
    pending = []
    for name, group in src.items():
        out = dst.create_group(name)
        for key, value in group.attrs.items():
            out.attrs[key] = value
        data = group["data"]
        n = data.shape[0]
        chunk = (data.chunks or (max(n, 1),))[0]
        ds = out.create_dataset(
            "data",
            shape=data.shape,
            dtype=data.dtype,
            maxshape=data.shape if n else (None,),
            chunks=(min(chunk, n) if n else chunk,),
            compression="gzip",
            compression_opts=4,
            shuffle=True,
            fillvalue=data.fillvalue,
        )
        for key, value in data.attrs.items():
            ds.attrs[key] = value
        if n:
            pending.append((ds, data))
    dst.flush()
    pieces = []
    for ds, data in pending:
        rows, chunk = data[()], ds.chunks[0]
        pieces += [(float(np.nan_to_num(rows["host_time"][at], nan=np.inf)), at, ds, rows)
                   for at in range(0, len(rows), chunk)]
    for _, at, ds, rows in sorted(pieces, key=lambda p: p[:2]):
        ds[at:at + ds.chunks[0]] = rows[at:at + ds.chunks[0]]
