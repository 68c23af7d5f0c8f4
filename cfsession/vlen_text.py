"""Declared lengths of variable-length text attributes, read from an HDF5 file's own bytes.

A variable-length text attribute stores, per value, its length (4 bytes) and where its bytes
are (a global heap object: 12 bytes). HDF5 allocates and clears that length before it reads the
heap object and finds it shorter (4 GB for 16 stored bytes of a crafted file), so
:func:`cfsession.guard.read_attrs` reads the lengths here first, from the file's bytes: the
object's header (and its continuation chunks), and for an object with many attributes the
blocks of the fractal heap holding them. Every attribute message of that name must be found and
within the caller's limit; one that cannot be checked (shared, in a filtered or huge-object
heap, an unknown layout) is reported as such. Everything read here is bounded (chunks, blocks,
messages, places a name is found), so a crafted file cannot make it slow. :class:`FileBytes`
also serves the guard's check of the text heaps (:func:`cfsession.guard.open_untrusted`).
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Callable, Iterator
from pathlib import Path

import h5py
import numpy as np

__all__ = ["FileBytes", "Texts", "declared_text_bytes", "is_vlen_text", "text_problem"]


_UNDEF = (1 << 64) - 1
_MAX_CHUNK = 1 << 20  # an object header chunk, a heap block read here (HDF5 writes <= 64 kB)
_MAX_CHUNKS = 64  # object header chunks, heap blocks of one object followed
_MAX_MESSAGES = 1 << 16  # in one object header (version 1 counts them in 2 bytes)
_MAX_PLACES = 100_000  # places an attribute's name is found while looking for its message
_MAX_VALUES = 1 << 16  # values of one attribute whose lengths are read (16 bytes each)
#: Values and declared bytes of each variable-length text attribute message, by name (``None``
#: for one that cannot be checked); or why they cannot be found.
Texts = dict[bytes, list[tuple[int, int] | None]] | str


class FileBytes:
    """The bytes of a file, read by offset: on disk with ``pread`` (a file cut short meanwhile
    reads short, where a memory map would kill the process), or an image in memory (the private
    copy HDF5 has open). A context manager; ``size`` is the length when opened."""

    def __init__(self, *, path: str | Path, image: bytes | None = None) -> None:
        self.image = image
        flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0)  # a FIFO put there since: no wait
        self.fd = os.open(path, flags) if image is None else -1
        self.size = len(image) if image is not None else os.fstat(self.fd).st_size

    def __enter__(self) -> FileBytes:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def read(self, at: int, n: int) -> bytes:
        if self.image is not None:
            return self.image[at:at + n]
        return os.pread(self.fd, n, at) if 0 <= at < 1 << 62 else b""

    def windows(self, overlap: int = 1 << 16) -> Iterator[tuple[int, bytes]]:
        """``(offset, bytes)`` of the whole file, 8 MiB at a time, each overlapping the next by
        ``overlap`` bytes (so a pattern that long is in one of them, maybe twice)."""
        at = 0
        while True:
            part = self.read(at, (8 << 20) + overlap)
            yield at, part
            if len(part) < (8 << 20) + overlap:
                return
            at += 8 << 20

    def find_all(self, pattern: bytes) -> Iterator[int]:
        """Offsets of ``pattern`` in the file."""
        for at, part in self.windows(len(pattern) - 1):
            i = part.find(pattern)
            while i >= 0:
                if i < 8 << 20:  # else it is in the next window too
                    yield at + i
                i = part.find(pattern, i + 1)

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)


def _u(b: bytes, at: int, n: int) -> int:
    return int.from_bytes(b[at:at + n], "little")


def _messages(raw: FileBytes, addr: int) -> Iterator[tuple[int, int, bytes]]:
    """``(type, flags, body)`` of each message of the object header at ``addr`` (version 1
    or 2), continuation chunks followed; ``ValueError`` for anything else."""
    head = raw.read(addr, 16).ljust(16, b"\xff")
    if head[:5] == b"OHDR\x02":
        flags = head[5]
        at = 6 + (16 if flags & 0x20 else 0) + (4 if flags & 0x10 else 0)
        width = 1 << (flags & 3)
        todo = [(addr + at + width, _u(raw.read(addr + at, width), 0, width))]
        size_of, gap = 6 if flags & 0x04 else 4, 4  # message header; a continuation's sig
    elif head[:1] == b"\x01":
        todo, size_of, gap = [(addr + 16, _u(head, 8, 4))], 8, 0
    else:
        raise ValueError("an object header of unknown version")
    seen: set[int] = set()
    count = 0
    while todo:
        start, size = todo.pop(0)
        if start in seen or len(seen) >= _MAX_CHUNKS or not 0 <= size <= _MAX_CHUNK:
            raise ValueError("an object header larger than HDF5 writes")
        seen.add(start)
        chunk, p = raw.read(start, size), 0
        while p + size_of <= len(chunk):
            count += 1
            if count > _MAX_MESSAGES:
                raise ValueError(f"an object header of more than {_MAX_MESSAGES} messages")
            if gap:  # version 2: type (1 byte), size (2), flags (1)[, creation order (2)]
                kind, n, mflags = chunk[p], _u(chunk, p + 1, 2), chunk[p + 3]
            else:  # version 1: type (2 bytes), size (2), flags (1), reserved (3)
                kind, n, mflags = _u(chunk, p, 2), _u(chunk, p + 2, 2), chunk[p + 4]
            body = chunk[p + size_of:p + size_of + n]
            p += size_of + n
            if kind == 0x10:  # continuation: address, length (with "OCHK" and checksum)
                todo.append((_u(body, 0, 8) + gap, _u(body, 8, 8) - 2 * gap))
            yield kind, mflags, body


def _points(space: bytes) -> int | None:
    """Values a dataspace message holds (``None``: not one HDF5 reads)."""
    if len(space) < 4 or space[0] not in (1, 2):
        return None
    rank, at = space[1], 8 if space[0] == 1 else 4
    kind = space[3] if space[0] == 2 else 1 if rank else 0  # 0 scalar, 1 simple, 2 null
    if kind != 1:
        return {0: 1, 2: 0}.get(kind)
    if len(space) < at + 8 * rank:
        return None
    return int(np.prod([_u(space, at + 8 * i, 8) for i in range(rank)], dtype=object))


def _attr_message(get: Callable[[int, int], bytes]) -> tuple[bytes, tuple[int, int] | None] | None:
    """``(name, (values, declared bytes))`` of the attribute message whose bytes ``get(lo, hi)``
    returns, if it holds variable-length text (``None`` for its sizes when they cannot be read);
    ``None`` for any other type. Reads only its header, type, dataspace and data."""
    head = get(0, 9)
    version = head[0] if len(head) == 9 else 0
    if version not in (1, 2, 3):
        return None  # HDF5 refuses it too
    start, align = (8, 8) if version == 1 else (8 + (version == 3), 1)
    n_name, n_type, n_space = _u(head, 2, 2), _u(head, 4, 2), _u(head, 6, 2)
    pad = lambda n: -(-n // align) * align  # noqa: E731
    name = get(start, start + max(n_name - 1, 0)).split(b"\0")[0]
    at_type = start + pad(n_name)
    at_space = at_type + pad(n_type)
    at_data = at_space + pad(n_space)
    if version > 1 and head[1] & 3:  # type or dataspace shared: stored elsewhere
        return name, None
    dtype = get(at_type, at_type + min(n_type, 16))
    if n_type < 16 or len(dtype) < 16 or dtype[0] & 0x0F != 9 or dtype[1] & 0x0F != 1:
        return None  # not variable-length text (a sequence is refused by its class)
    values = _points(get(at_space, at_space + n_space))
    if values is None or values > _MAX_VALUES:
        return name, None
    data = get(at_data, at_data + 16 * values)
    if len(data) < 16 * values:
        return name, None
    base = max(_u(dtype, 12, 4), 1)  # bytes of one character, as the file declares
    lengths = np.frombuffer(data, "<u4")[::4].astype(np.uint64)  # (length, heap address, index)
    return name, (values, base * int(lengths.sum()))


def _named(raw: FileBytes, spans: Iterator[tuple[int, bytes]], names: list[bytes],
           found: dict[bytes, list[tuple[int, int] | None]]) -> None:
    """Add to ``found`` the attribute messages named ``names`` found in ``spans`` (file offset,
    bytes): each place a name is followed by its terminating zero and preceded by the header of
    an attribute message of some version with that name's length."""
    seen = 0
    for at, span in spans:
        for name in names:
            i = span.find(name + b"\0")
            while i >= 0:
                seen += 1
                if seen > _MAX_PLACES:
                    raise ValueError(f"attribute names found more than {_MAX_PLACES} times")
                for version, back in ((1, 8), (2, 8), (3, 9)):  # the versions' header sizes
                    head = span[i - back:i] if i >= back else b""
                    if head[:1] == bytes([version]) and _u(head, 2, 2) == len(name) + 1:
                        got = _attr_message(lambda lo, hi, o=at + i - back:
                                            raw.read(o + lo, hi - lo))
                        if got is not None and got[0] == name:
                            found.setdefault(name, []).append(got[1])
                i = span.find(name + b"\0", i + 1)


def _dense(raw: FileBytes, info: bytes, names: list[bytes],
           found: dict[bytes, list[tuple[int, int] | None]]) -> None:
    """Add to ``found`` the attribute messages named ``names`` in the fractal heap an attribute
    info message names (where an object with many attributes keeps them): every direct block
    of it, or if it holds huge objects (each stored by itself), the whole file."""
    heap = _u(info, 2 + 2 * (info[1] & 1), 8) if len(info) >= 10 else _UNDEF
    if heap == _UNDEF:
        return
    head = raw.read(heap, 128)
    if head[:5] != b"FRHP\x00" or _u(head, 7, 2):
        raise ValueError("many attributes in a heap that is not one HDF5 writes, or filtered")
    if _u(head, 22, 8) != _UNDEF:  # huge objects: whole messages, anywhere in the file
        _named(raw, raw.windows(), names, found)
        return
    size = _u(head, 120, 8)  # largest direct block
    blocks = list(itertools.islice(raw.find_all(b"FHDB\x00" + heap.to_bytes(8, "little")),
                                   _MAX_CHUNKS + 1))
    if len(blocks) > _MAX_CHUNKS or size > _MAX_CHUNK:
        raise ValueError("many attributes in a heap larger than HDF5 writes")
    _named(raw, ((at, raw.read(at, size)) for at in blocks), names, found)


def declared_text_bytes(obj: h5py.HLObject, *, image: bytes | None = None) -> Texts:
    """Values and declared bytes of every variable-length text attribute message of ``obj``,
    by name (``None`` for one that cannot be checked), read from the file's bytes (``image``:
    the private copy HDF5 has open instead of the file on disk); or why they cannot be found."""
    if obj.file.driver != "sec2" and image is None:
        return "(a file not opened by open_untrusted)"
    try:
        with FileBytes(path=obj.file.filename, image=image) as raw:
            head = raw.read(0, 16)
            if (head[13:15] if head[8:9] in (b"\0", b"\1") else head[9:11]) != b"\x08\x08":
                return "(not 8-byte addresses)"
            found: dict[bytes, list[tuple[int, int] | None]] = {}
            infos = []
            for kind, flags, body in _messages(raw, h5py.h5o.get_info(obj.id).addr):
                if kind == 0x0C and flags & 0x02:
                    return "(a shared attribute message)"
                if kind == 0x0C and (got := _attr_message(lambda lo, hi, b=body: b[lo:hi])):
                    found.setdefault(got[0], []).append(got[1])
                elif kind == 0x15:
                    infos.append(body)
            names = [n.encode() for n in obj.attrs
                     if infos and is_vlen_text(obj.attrs.get_id(n))]
            for info in infos:
                _dense(raw, info, names, found)
    except (ValueError, OSError) as exc:
        return f"({exc})"
    return found


def is_vlen_text(aid: h5py.h5a.AttrID) -> bool:
    """Whether an attribute is variable-length text."""
    tid = aid.get_type()
    return tid.get_class() == h5py.h5t.STRING and tid.is_variable_str()


def text_problem(texts: Texts, name: str, values: int, *, limit: int) -> str | None:
    """Why the variable-length text attribute ``name`` (of ``values`` values) is not read: it
    cannot be checked, or it declares more than ``limit`` bytes; ``None`` if it can be."""
    if isinstance(texts, str):
        return f"not checked {texts}"
    sizes = texts.get(name.encode(), [])
    if any(s is None for s in sizes):
        return "not checked (an attribute message of that name is shared or cut short)"
    sizes = [s for s in sizes if s[0] == values]  # others: stale, freed copies
    if not sizes:
        return "not checked (its attribute message was not found where HDF5 keeps it)"
    most = max(s[1] for s in sizes)
    return f"of {most} declared bytes" if most > limit else None
