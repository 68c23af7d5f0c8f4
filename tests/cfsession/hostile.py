"""Crafted HDF5 files for the guard's tests: bytes patched where h5py cannot write them.

:func:`declare_text_length` makes a variable-length text attribute declare a length its heap
object does not have. Each value of such an attribute is stored as its length (4 bytes) and its
global heap object's place (collection address, 8 bytes; index, 4 bytes); HDF5 allocates and
clears the declared length before it reads the object. The checksum of the object header chunk
or fractal heap block holding the value is recomputed, so HDF5 reads the file as before.
"""

from __future__ import annotations

from pathlib import Path

from cfsession.guard import lookup3


def _u(data: bytes | bytearray, at: int, n: int) -> int:
    return int.from_bytes(data[at:at + n], "little")


def declare_text_length(path: Path, text: bytes, length: int) -> None:
    """Make the attribute value whose text is ``text`` (found once in the file's global heap)
    declare ``length`` bytes."""
    data = bytearray(path.read_bytes())
    assert data.count(text) == 1, "the text must be found once"
    obj = data.find(text) - 16  # heap object header: index (2), references (2), 4, size (8)
    assert _u(data, obj + 8, 8) == len(text)
    collection = data.rfind(b"GCOL", 0, obj)
    value = len(text).to_bytes(4, "little") + collection.to_bytes(8, "little") + data[obj:obj + 2] \
        + bytes(2)
    assert data.count(value) == 1, "the attribute value must be found once"
    at = data.find(value)
    holder = max(data.rfind(sig, 0, at) for sig in (b"OHDR", b"OCHK", b"FHDB"))
    if holder >= 0 and data[holder:holder + 4] == b"FHDB":  # the block checksummed with its
        heap = _u(data, holder + 5, 8)  # own field zeroed; a root block is the starting size
        size, field = _u(data, heap + 112, 8), holder + 13 + (_u(data, heap + 128, 2) + 7) // 8
        stored = _u(data, field, 4)
        data[field:field + 4] = bytes(4)
        assert lookup3(bytes(data[holder:holder + size])) == stored, "not a root direct block"
        data[at:at + 4] = length.to_bytes(4, "little")
        data[field:field + 4] = lookup3(bytes(data[holder:holder + size])).to_bytes(4, "little")
    elif holder >= 0 and at - holder < 1 << 16:  # version 2 object header chunk: the checksum
        end = next(e for e in range(at + 16, len(data) - 3)  # follows its messages
                   if _u(data, e, 4) == lookup3(bytes(data[holder:e])))
        data[at:at + 4] = length.to_bytes(4, "little")
        data[end:end + 4] = lookup3(bytes(data[holder:end])).to_bytes(4, "little")
    else:  # version 1 object header: no checksum
        data[at:at + 4] = length.to_bytes(4, "little")
    path.write_bytes(bytes(data))


def mark_killed(path: Path) -> None:
    """Set the superblock's status flags, as a writer that died leaves them (version 2/3)."""
    data = bytearray(path.read_bytes())
    data[11] = 0x05  # open for writing, SWMR writing
    data[44:48] = lookup3(bytes(data[:44])).to_bytes(4, "little")
    path.write_bytes(bytes(data))
