"""Opening session files that may be damaged or crafted, without hanging or reading elsewhere.

A session file comes from anywhere (a colleague, a crashed writer, a download), so the reader
opens it only through :func:`open_untrusted` and checks every object before reading it
(:func:`check_dataset`, :func:`hard_links`, :func:`read_attrs`); anything refused is one
:class:`~cfsession.errors.SessionError` line. The same checks serve any HDF5 file from
elsewhere (``sysid`` model files: ``kind`` names the file in messages; :func:`check_storage`
is the part of :func:`check_dataset` that holds for every dataset).

**Files not closed cleanly.** A writer that died leaves the superblock's status flags set
(file open for writing, SWMR writing). HDF5 reads such a file only in SWMR mode, where a
metadata checksum failure is retried, with back-off, for over a minute per object: one flipped
byte hangs every tool. Instead, :func:`open_untrusted` reads the superblock itself: a file whose
flags are set is read into memory (at most :data:`MAX_UNCLEAN_BYTES`), the flags are cleared in
that private copy (its checksum recomputed) and the copy is opened read-only in the ordinary
mode, where a checksum failure is an immediate error. No SWMR read, so nothing to time out;
the file on disk is never changed.

**Files cut short.** A file shorter than the end of file its superblock stores (a copy
interrupted, a card pulled) is read the same way by :func:`open_cut` (the session reader; model
files stay refused by :func:`open_untrusted`): its bytes, zero-padded up to the stored end, are
the private copy, provided that end is at most :data:`MAX_UNCLEAN_BYTES` and at most
:data:`MAX_CUT_RATIO` times the real size plus :data:`CUT_SLACK_BYTES` (a file holding its first
1.5 % still reads; a superblock claiming gigabytes for a few kilobytes does not), and the
superblock's checksum holds. HDF5 finds every piece of metadata beyond the cut by its checksum,
an immediate error; data chunks have none, so the reader (:func:`lost_chunks`) treats every chunk
lying even partly beyond the cut as lost rather than reading its zeros.

**What is refused** (before any data is read): a path that is not a regular file; soft and
external links; datasets with external storage (they read other files: ``/etc/passwd``, a FIFO
that blocks for ever) and virtual datasets; datasets whose declared size exceeds what the file
could hold (chunked: the allocated chunks plus slack; contiguous: its storage; any: more than
:data:`MAX_EXPANSION` times the file size); stream datasets that are not one-dimensional or
whose fields are not numbers or fixed-length text; more than :data:`MAX_OBJECTS` streams or
attributes. Attributes larger than :data:`MAX_ATTR_BYTES`, or of a type other than numbers and
text, are skipped unread and listed as problems; so is variable-length text whose declared length
(read from the file's own bytes by :mod:`cfsession.vlen_text`: HDF5 allocates and clears what it
declares before it finds out it is false, 4 GB for 16 stored bytes) exceeds that or cannot be found.
"""

from __future__ import annotations

import io
import os
import shlex
import weakref
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, Literal, NamedTuple

import h5py
import numpy as np

from cfsession.errors import SessionError
from cfsession.vlen_text import FileBytes, Texts, declared_text_bytes, is_vlen_text, text_problem

__all__ = ["CUT_SLACK_BYTES", "FLIGHT_LOGS", "HDF5_SIGNATURE", "MAX_ATTR_BYTES", "MAX_CUT_RATIO",
           "MAX_EXPANSION", "MAX_OBJECTS", "MAX_UNCLEAN_BYTES", "Cut", "check_dataset",
           "check_storage", "file_size", "flight_log_kind", "hard_links", "lost_chunks",
           "open_cut", "open_untrusted", "read_attrs", "short_error"]

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"
#: The flight logs ``groundstation import`` makes sessions of, by :func:`flight_log_kind`.
FLIGHT_LOGS = {"usd": "Crazyflie uSD-card deck log", "csv": "cfclient log CSV"}
_USD_MAGIC = b"\xbc"  # the deck log's header byte
_CSV_HEADER = b"Timestamp"  # the first column of a cfclient "log to file" CSV
_UTF8_BOM = b"\xef\xbb\xbf"  # Excel's save of a CSV


def flight_log_kind(head: bytes) -> Literal["usd", "csv"] | None:
    """``"usd"`` or ``"csv"`` (:data:`FLIGHT_LOGS`) from a file's first bytes (at least 12),
    None for anything else: the one check of the importer (``groundstation import``) and of
    the hint that a session reader gives for such a file."""
    head = head.removeprefix(_UTF8_BOM)
    if head[:1] == _USD_MAGIC:
        return "usd"
    if head.startswith(_CSV_HEADER):
        return "csv"
    return None
MAX_UNCLEAN_BYTES = 1 << 30
"""Largest file not closed cleanly, or stored end of a file cut short, that is read (into
memory, see the module docstring)."""
MAX_CUT_RATIO = 64
CUT_SLACK_BYTES = 1 << 20
"""A file cut short is read when its stored end of file is at most ``MAX_CUT_RATIO`` times its
real size plus ``CUT_SLACK_BYTES`` (and at most :data:`MAX_UNCLEAN_BYTES`)."""
MAX_EXPANSION = 1000
"""Rows may declare at most this many times the file's size in bytes (gzip's best ratio)."""
MAX_OBJECTS = 1024
"""Most streams in a file, and most attributes on one object."""
MAX_ATTR_BYTES = 1 << 20
_ATTR_CLASSES = (h5py.h5t.INTEGER, h5py.h5t.FLOAT, h5py.h5t.STRING)
"""Attribute types read: numbers and text (and h5py's two-member boolean enum). Others are
skipped unread: a damaged string type that reads as a variable-length sequence crashed the
interpreter inside HDF5."""
_CLASS_NAMES = {h5py.h5t.TIME: "time", h5py.h5t.BITFIELD: "bitfield",
                h5py.h5t.OPAQUE: "opaque", h5py.h5t.COMPOUND: "compound",
                h5py.h5t.REFERENCE: "reference", h5py.h5t.ENUM: "enum",
                h5py.h5t.VLEN: "variable-length sequence", h5py.h5t.ARRAY: "array"}
MAX_CHUNK_BYTES = 16 << 20
MAX_ROW_BYTES = 1 << 16
_CHUNK_SLACK = 2  # chunks a killed writer may have resized into but not yet written


# ---------------------------------------------------------------------- superblock


def _rot(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & 0xFFFFFFFF


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 ``hashlittle``: HDF5's metadata checksum (``H5_checksum_lookup3``)."""
    m = 0xFFFFFFFF
    a = b = c = (0xDEADBEEF + len(data) + initval) & m
    n = len(data)
    i = 0
    while n - i > 12:
        a = (a + int.from_bytes(data[i:i + 4], "little")) & m
        b = (b + int.from_bytes(data[i + 4:i + 8], "little")) & m
        c = (c + int.from_bytes(data[i + 8:i + 12], "little")) & m
        a = (a - c) & m; a ^= _rot(c, 4); c = (c + b) & m  # noqa: E702
        b = (b - a) & m; b ^= _rot(a, 6); a = (a + c) & m  # noqa: E702
        c = (c - b) & m; c ^= _rot(b, 8); b = (b + a) & m  # noqa: E702
        a = (a - c) & m; a ^= _rot(c, 16); c = (c + b) & m  # noqa: E702
        b = (b - a) & m; b ^= _rot(a, 19); a = (a + c) & m  # noqa: E702
        c = (c - b) & m; c ^= _rot(b, 4); b = (b + a) & m  # noqa: E702
        i += 12
    if n - i == 0:
        return c
    tail = data[i:].ljust(12, b"\0")
    a = (a + int.from_bytes(tail[0:4], "little")) & m
    b = (b + int.from_bytes(tail[4:8], "little")) & m
    c = (c + int.from_bytes(tail[8:12], "little")) & m
    c ^= b; c = (c - _rot(b, 14)) & m  # noqa: E702
    a ^= c; a = (a - _rot(c, 11)) & m  # noqa: E702
    b ^= a; b = (b - _rot(a, 25)) & m  # noqa: E702
    c ^= b; c = (c - _rot(b, 16)) & m  # noqa: E702
    a ^= c; a = (a - _rot(c, 4)) & m  # noqa: E702
    b ^= a; b = (b - _rot(a, 14)) & m  # noqa: E702
    c ^= b; c = (c - _rot(b, 24)) & m  # noqa: E702
    return c


def _superblock(head: bytes) -> tuple[int, int, int] | None:
    """``(status flags, stored end of file, checksum offset)`` of a version 2/3 superblock with
    8-byte addresses at offset 0, or ``None`` for any other layout."""
    if len(head) < 48 or head[:8] != HDF5_SIGNATURE or head[8] not in (2, 3) or head[9] != 8:
        return None
    return head[11], int.from_bytes(head[28:36], "little"), 44


class Cut(NamedTuple):
    """A file cut short: ``size`` bytes of the ``stored_eof`` its superblock says it has."""

    size: int
    stored_eof: int

    def __str__(self) -> str:
        return f"truncated at {self.size} of {self.stored_eof} bytes"


def _private_copy(path: Path, size: int, stored_eof: int) -> tuple[_Image, Cut | None]:
    """The file's bytes, zero-padded up to ``stored_eof`` when shorter (then also the
    :class:`Cut`), with the superblock's status flags cleared (checksum recomputed): one piece
    of code for files not closed cleanly and files cut short."""
    if max(size, stored_eof) > MAX_UNCLEAN_BYTES:
        what = "cut short" if stored_eof > size else "not closed cleanly"
        raise SessionError(f"{path}: {what} and {max(size, stored_eof) / 2**20:.0f} MiB, more "
                           f"than the {MAX_UNCLEAN_BYTES >> 20} MiB read to recover such a file")
    data = bytearray(path.read_bytes()[:MAX_UNCLEAN_BYTES])
    cut = None
    if len(data) < stored_eof:  # cut short (by the time it was read, too)
        cut = Cut(len(data), stored_eof)
        data.extend(bytes(stored_eof - len(data)))
        _seal_heaps(data, cut.size)
    data[11] = 0
    data[44:48] = lookup3(bytes(data[:44])).to_bytes(4, "little")
    copy = _Image(bytes(data))
    _IMAGES[repr(copy)] = copy  # h5py names a file object by its repr
    return copy, cut


_GCOL_MIN = 4096  # HDF5's smallest global heap collection (H5HG_MINSIZE)


def _heap_object(head: bytes) -> tuple[int, int]:
    """``(index, bytes taken)`` of a global heap object from its 16-byte header: index 0 is
    the collection's free space, its size the whole; any other, the header and its data
    padded to 8 bytes."""
    idx, size = int.from_bytes(head[0:2], "little"), int.from_bytes(head[8:16], "little")
    return idx, size if idx == 0 else 16 + (size + 7) // 8 * 8


def _seal_heaps(data: bytearray, cut: int) -> None:
    """Make each text heap (global heap collection) that runs past ``cut`` end there: its
    objects lying wholly before the cut are kept, the rest of it becomes free space (HDF5
    would walk zero padding for ever: an empty free-space object does not advance its parser),
    so a text beyond the cut is not found rather than read as zeros. Only in the private copy."""
    at = data.find(b"GCOL", 0, cut)
    while at >= 0:
        size = int.from_bytes(data[at + 8:at + 16], "little")
        end = at + size
        if (data[at + 4] == 1 and not any(data[at + 5:at + 8]) and size >= _GCOL_MIN
                and at + 16 <= cut < end <= len(data)):
            p = at + 16
            while p + 16 <= cut:
                idx, need = _heap_object(data[p:p + 16])
                if idx == 0 or need == 0 or p + need > cut:
                    break
                p += need
            if p + 16 <= end:
                data[p:p + 16] = bytes(8) + (end - p).to_bytes(8, "little")
        at = data.find(b"GCOL", at + 4, cut)


class _Image(io.BytesIO):
    """A private copy opened by HDF5 whose bytes :func:`read_attrs` checks as well."""

    def __init__(self, data: bytes) -> None:
        super().__init__(data)  # shares ``data`` until written to, which HDF5 never does
        self.image = data


_IMAGES: weakref.WeakValueDictionary[str, _Image] = weakref.WeakValueDictionary()


def _heap_loop(raw: FileBytes) -> int | None:
    """Offset of a global heap collection (``GCOL``: where variable-length strings live)
    whose object list HDF5 would walk for ever (a free-space object of size 0 does not
    advance its parser; a size near 2**64 wraps it back), or ``None``. Read in pieces."""
    for at in raw.find_all(b"GCOL"):
        size = int.from_bytes(raw.read(at + 8, 8), "little")
        end = at + min(size, raw.size - at)
        p, buf_at, buf = at + 16, 0, b""
        while p + 16 <= end:
            if p + 16 > buf_at + len(buf):
                buf_at, buf = p, raw.read(p, min(8 << 20, end - p))
                if len(buf) < 16:  # cut short since it was opened
                    break
            head = buf[p - buf_at:p - buf_at + 16]
            _, need = _heap_object(head)
            if need == 0 or need >= 1 << 62:
                return at
            p += need
    return None


def open_untrusted(path: Path, *, kind: str = "session") -> tuple[h5py.File, bool]:
    """Open ``path`` read-only without SWMR; returns the file and whether its superblock says
    it was closed cleanly. One-line :class:`SessionError` when it cannot be opened (``kind``:
    what the file should be, for the message), or is cut short (:func:`open_cut` reads that)."""
    f, clean, _cut = _open(path, kind=kind, cut_ok=False)
    return f, clean


def open_cut(path: Path, *, kind: str = "session") -> tuple[h5py.File, bool, Cut | None]:
    """:func:`open_untrusted`, but a file cut short (see the module docstring) is opened from
    its zero-padded copy; the :class:`Cut` then says where (``None`` for a whole file). Whoever
    reads it must not believe a byte beyond ``cut.size``: :func:`lost_chunks`."""
    return _open(path, kind=kind, cut_ok=True)


def _open(path: Path, *, kind: str, cut_ok: bool) -> tuple[h5py.File, bool, Cut | None]:
    try:
        st = path.stat()
        if path.is_dir():
            raise SessionError(f"{path}: is a folder, not a {kind} file")
        if not path.is_file():
            raise SessionError(f"{path}: not a regular file (a device, FIFO or socket), so not a "
                               f"{kind} file")
        with open(path, "rb") as fh:
            head = fh.read(48)
    except OSError as exc:
        raise SessionError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if head[:8] != HDF5_SIGNATURE:
        log_kind = flight_log_kind(head) if kind == "session" else None
        raise SessionError(f"{path}: not an HDF5 file, so not a {kind} file" + (
            "" if log_kind is None else f": it is a {FLIGHT_LOGS[log_kind]}; make a session "
            f"of it with `groundstation import {shlex.quote(str(path))} --out DIR`"))
    if len(head) < 48:
        raise SessionError(f"{path}: damaged beyond repair (truncated at {len(head)} bytes, "
                           "inside its superblock)")
    sb = _superblock(head)
    cut: Cut | None = None
    if sb is not None and sb[1] > st.st_size:
        cut = Cut(st.st_size, sb[1])
        if not cut_ok:
            raise SessionError(f"{path}: damaged beyond repair ({cut})")
        if lookup3(head[:sb[2]]) != int.from_bytes(head[sb[2]:sb[2] + 4], "little"):
            raise SessionError(f"{path}: damaged beyond repair ({cut}, and its superblock's "
                               "checksum does not match)")
        if sb[1] > MAX_CUT_RATIO * st.st_size + CUT_SLACK_BYTES:
            raise SessionError(f"{path}: damaged beyond repair ({cut}: a stored end more "
                               f"than {MAX_CUT_RATIO} times the size is no file cut short)")
    flagged = sb is not None and sb[0] != 0
    copy = None
    if flagged or cut is not None:
        try:
            copy, cut = _private_copy(path, st.st_size, sb[1])  # type: ignore[index]
        except OSError as exc:
            raise SessionError(f"{path}: cannot read ({exc.strerror or exc})") from None
    try:
        with FileBytes(path=path, image=None if copy is None else copy.image) as raw:
            loop = _heap_loop(raw)
    except OSError as exc:
        raise SessionError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if loop is not None:
        raise SessionError(f"{path}: damaged beyond repair (text heap at byte {loop} would be "
                           "read for ever)")
    try:
        if copy is not None:
            return h5py.File(copy, "r", locking=False), not flagged, cut
        return h5py.File(path, "r", locking=False), True, None
    except SessionError:
        raise
    except Exception as exc:  # h5py: OSError; the file-object driver passes others through
        why = short_error(exc) if cut is None else f"{cut}; {short_error(exc)}"
        raise SessionError(f"{path}: damaged beyond repair ({why})") from None


def lost_chunks(ds: h5py.Dataset, cut: Cut | None) -> list[int]:
    """The first rows (sorted) of the chunks of a chunked one-dimensional dataset that lie, even
    partly, beyond ``cut`` (the file was cut short there): zeros read from the padded copy, not
    data. ``[]`` for a whole file. HDF5 errors (the chunk index itself lost) pass through."""
    if cut is None or ds.chunks is None:
        return []
    starts: list[int] = []

    def visit(info: Any) -> None:
        if info.byte_offset + info.size > cut.size:
            starts.append(int(info.chunk_offset[0]))

    if hasattr(ds.id, "chunk_iter"):
        ds.id.chunk_iter(visit)
    else:  # h5py < 3.8
        for i in range(ds.id.get_num_chunks()):
            visit(ds.id.get_chunk_info(i))
    return sorted(starts)


def short_error(exc: BaseException) -> str:
    """The first line of an (HDF5) error, without its internals: text for a one-line message."""
    text = exc.args[0] if isinstance(exc, KeyError) and exc.args else exc  # no quotes
    msg = str(text).strip().splitlines()[0] if str(text).strip() else type(exc).__name__
    first = msg.split("(")[0].strip() or type(exc).__name__
    return first[:200]


# ---------------------------------------------------------------------- objects


def hard_links(group: h5py.Group, *, where: str, kind: str = "session",
               unreadable: Callable[[str, Exception], None] | None = None,
               ) -> Iterator[tuple[str, Any]]:
    """``(name, object)`` for each member of ``group``; a soft or external link, or more than
    :data:`MAX_OBJECTS` members, is a one-line :class:`SessionError`. A member HDF5 cannot
    open (its header damaged or beyond a cut) is an error, or, given ``unreadable``, passed
    to it (with the error) and skipped."""
    names = list(group.keys())
    if len(names) > MAX_OBJECTS:
        raise SessionError(f"{where}: {len(names)} objects, more than a {kind} has "
                           f"({MAX_OBJECTS})")
    for name in names:
        try:
            link = group.get(name, getlink=True)
            if isinstance(link, h5py.ExternalLink):
                raise SessionError(f"{where}: {name!r} links to another file "
                                   f"({link.filename}); refusing to follow it")
            if isinstance(link, h5py.SoftLink):
                raise SessionError(f"{where}: {name!r} is a soft link ({link.path}); {kind} "
                                   "files have none, refusing to follow it")
            obj = group[name]
        except SessionError:
            raise
        except Exception as exc:
            if unreadable is None:
                raise
            unreadable(name, exc)
            continue
        yield name, obj


def read_attrs(obj: h5py.HLObject, *, where: str, problems: list[str],
               kind: str = "session") -> dict[str, Any]:
    """The attributes of ``obj`` that can be read; one too large or unreadable is skipped
    and listed in ``problems``."""
    attrs = obj.attrs
    names = list(attrs.keys())
    if len(names) > MAX_OBJECTS:
        raise SessionError(f"{where}: {len(names)} attributes, more than a {kind} has "
                           f"({MAX_OBJECTS})")
    out: dict[str, Any] = {}
    texts: Texts | None = None
    for name in names:
        try:
            aid = attrs.get_id(name)
            size = aid.get_storage_size()
            if size > MAX_ATTR_BYTES:
                problems.append(f"{where}: attribute {name!r} skipped ({size} bytes)")
                continue
            type_class = aid.get_type().get_class()
            boolean = type_class == h5py.h5t.ENUM and aid.dtype == np.bool_  # h5py's bool
            if type_class not in _ATTR_CLASSES and not boolean:
                problems.append(f"{where}: attribute {name!r} skipped (HDF5 type class "
                                f"{_CLASS_NAMES.get(type_class, type_class)}, not a number "
                                "or text)")
                continue
            if is_vlen_text(aid):
                if texts is None:
                    image = _IMAGES.get(obj.file.filename) if obj.file.driver == "fileobj" else None
                    texts = declared_text_bytes(obj, image=None if image is None else image.image)
                why = text_problem(texts, name, aid.get_space().get_simple_extent_npoints(),
                                   limit=MAX_ATTR_BYTES)
                if why:
                    problems.append(f"{where}: attribute {name!r} skipped (variable-length text "
                                    f"{why})")
                    continue
            out[name] = attrs[name]
        except Exception as exc:
            problems.append(f"{where}: attribute {name!r} unreadable ({short_error(exc)})")
    return out


def _field_ok(dt: np.dtype) -> bool:
    return dt.subdtype is None and (dt.kind in "biuf" or (dt.kind == "S" and dt.itemsize > 0))


def _extent(shape: tuple[int, ...]) -> str:
    return f"{shape[0]} rows" if len(shape) == 1 else f"shape {shape}"


def check_storage(ds: h5py.Dataset, *, where: str, file_size: int) -> None:
    """Refuse, in one line, a dataset of any kind that reads elsewhere (virtual, external
    storage) or declares more than the file could hold (see the module docstring): checked
    before it is read, so nothing is allocated for a crafted shape."""
    dcpl = ds.id.get_create_plist()
    if ds.is_virtual:
        raise SessionError(f"{where}: a virtual dataset (reads other files); refusing it")
    if dcpl.get_external_count():
        name = dcpl.get_external(0)[0].decode(errors="replace")
        raise SessionError(f"{where}: data stored outside the file ({name}); refusing to read it")
    shape = ds.shape or ()
    itemsize = ds.dtype.itemsize
    items = int(np.prod(shape, dtype=object))
    nbytes = items * itemsize
    if nbytes > MAX_EXPANSION * max(file_size, 1024):
        raise SessionError(f"{where}: declares {_extent(shape)} ({nbytes} bytes), more than a "
                           f"{file_size}-byte file can hold")
    if ds.chunks is not None:
        chunk = int(np.prod(ds.chunks, dtype=object))
        if chunk * itemsize > MAX_CHUNK_BYTES:
            raise SessionError(f"{where}: chunks of {_extent(ds.chunks)} ({chunk * itemsize} "
                               f"bytes), more than {MAX_CHUNK_BYTES >> 20} MiB; refusing them")
        stored = (ds.id.get_num_chunks() + _CHUNK_SLACK) * chunk
        if items > stored:
            raise SessionError(f"{where}: declares {_extent(shape)} but stores at most {stored}")
    elif dcpl.get_layout() == h5py.h5d.CONTIGUOUS and nbytes > ds.id.get_storage_size():
        raise SessionError(f"{where}: declares {_extent(shape)} but stores "
                           f"{ds.id.get_storage_size() // max(itemsize, 1)}")


def check_dataset(ds: h5py.Dataset, *, where: str, file_size: int) -> None:
    """Refuse, in one line, a stream dataset that reads elsewhere or more than the file holds
    (:func:`check_storage`), or that is not rows of named number or text fields."""
    check_storage(ds, where=where, file_size=file_size)
    dt = ds.dtype
    if dt.names is None or not dt.names:
        raise SessionError(f"{where}: dtype {dt}, not a session stream (rows of named fields)")
    bad = [n for n in dt.names if not _field_ok(dt.fields[n][0])]
    if bad:
        raise SessionError(f"{where}: field {bad[0]!r} has type {dt.fields[bad[0]][0]}; "
                           "session streams hold numbers and fixed-length text only")
    if "host_time" not in dt.names or dt.fields["host_time"][0].kind != "f":
        raise SessionError(f"{where}: no floating-point host_time field; not a session stream")
    if dt.itemsize > MAX_ROW_BYTES:
        raise SessionError(f"{where}: rows of {dt.itemsize} bytes; not a session stream")
    if ds.ndim != 1:
        raise SessionError(f"{where}: shape {ds.shape}; session streams are one-dimensional")


def file_size(f: h5py.File, path: Path) -> int:
    """Bytes of the open file (its in-memory copy's, for a recovered one)."""
    try:
        return int(f.id.get_filesize())
    except Exception:
        return os.stat(path).st_size
