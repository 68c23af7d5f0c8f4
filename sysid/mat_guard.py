"""The shape of a MATLAB 5 ``.mat`` file checked before scipy reads it (model files are untrusted).

scipy's ``loadmat`` inflates compressed elements (one may grow a thousandfold) and recurses in C
through nested cells (9 MB of them crashed the interpreter). :func:`check_mat` walks the element
tags in Python first and lets through only what :func:`sysid.model_io.save` writes: MATLAB 5,
uncompressed real arrays of numbers or text, and at top level cells of those. Every element must
fit inside its parent, and every array hold the subelements of its class at the sizes its
dimensions say (a complex flag with no imaginary part crashed scipy's reader), and no part may
be larger than a model's (:class:`Limits`: crafted dimensions, cells and texts cost seconds and
gigabytes). The header must be MATLAB 5's (scipy reads a file with a zero in its first four bytes
as MATLAB 4, past this walk). Anything else is a ``ValueError`` naming the byte where it is.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

__all__ = ["Limits", "check_mat"]

# MAT-file element types and array classes (MATLAB 5 format): what check_mat lets through
_MI_INT8, _MI_INT32, _MI_UINT32, _MI_MATRIX = 1, 5, 6, 14
_MX_CELL, _MX_CHAR = 1, 4
_MX_NUMBERS = range(6, 16)  # double, single, int8 ... uint64
#: Bytes per value of the element types a numeric array's data may be stored in.
_NUMBER_BYTES = {1: 1, 2: 1, 3: 2, 4: 2, 5: 4, 6: 4, 7: 4, 9: 8, 12: 8, 13: 8}
#: Bytes per character of the element types a char array's data may be stored in (UTF-8: 1-4).
_CHAR_BYTES = {1: (1, 1), 2: (1, 1), 4: (2, 2), 16: (1, 4), 17: (2, 2), 18: (4, 4)}
_FLAG_BITS = 0x0E  # complex, global, logical: sysid writes none of them
_MAX_NDIMS = 4  # sysid writes 2; more would only make the product of the dimensions costly


@dataclass(frozen=True)
class Limits:
    """How large a sysid model's MAT file may be in its parts: values in one numeric array (a
    2000 x 2000 matrix), rows or columns of one (``side``: states, inputs, outputs), texts in
    one cell (names of 2000 channels), bytes of one text (the provenance), top-level
    variables. Messages hold no parentheses: the model reader keeps a message up to its first
    (:func:`cfsession.guard.short_error`)."""

    values: int = 2000 * 2000
    side: int = 2000
    cells: int = 2000
    text_bytes: int = 1 << 20
    variables: int = 64


def _mat_tag(data: bytes, pos: int, order: str, end: int) -> tuple[int, int, int, int]:
    """``(type, payload start, payload bytes, next position)`` of the MAT element at ``pos``."""
    if pos + 8 > end:
        raise ValueError(f"MAT element at byte {pos} is cut off")
    word, nbytes = struct.unpack_from(order + "II", data, pos)
    if word >> 16:  # small data element: type and size in one word, data in the next four
        if word >> 16 > 4:
            raise ValueError(f"MAT small element at byte {pos} declares {word >> 16} bytes")
        return word & 0xFFFF, pos + 4, word >> 16, pos + 8
    after = pos + 8 + nbytes + (-nbytes % 8)
    if pos + 8 + nbytes > end:
        raise ValueError(f"MAT element at byte {pos} declares {nbytes} bytes past the end")
    return word, pos + 8, nbytes, min(after, end)


def _header(data: bytes, pos: int, order: str, end: int
            ) -> tuple[int, tuple[int, ...], str, int]:
    """``(class, shape, name, position after the name)`` of the array whose payload starts at
    ``pos``: its flags (no complex, global or logical bit), dimensions and name."""
    kind, flags, size, p = _mat_tag(data, pos, order, end)
    if kind != _MI_UINT32 or size != 8:
        raise ValueError(f"MAT array at byte {pos} has no array flags")
    word = struct.unpack_from(order + "I", data, flags)[0]
    if word >> 8 & _FLAG_BITS:
        raise ValueError(f"MAT array at byte {pos} is complex, global or logical; sysid writes "
                         "real arrays only")
    kind, dims, size, p = _mat_tag(data, p, order, end)
    if kind != _MI_INT32 or size < 8 or size % 4:
        raise ValueError(f"MAT array at byte {pos} has no dimensions")
    if size // 4 > _MAX_NDIMS:
        raise ValueError(f"MAT array at byte {pos} has {size // 4} dimensions; sysid writes 2")
    shape = struct.unpack_from(f"{order}{size // 4}i", data, dims)
    if min(shape) < 0:
        raise ValueError(f"MAT array at byte {pos} has a negative dimension")
    kind, name, size, p = _mat_tag(data, p, order, end)
    if kind != _MI_INT8:
        raise ValueError(f"MAT array at byte {pos} has no name")
    return word & 0xFF, shape, data[name:name + min(size, 64)].decode("latin-1"), p


def _mat_array(data: bytes, pos: int, order: str, *, end: int, in_cell: bool,
               limits: Limits) -> int:
    """Check the array element at ``pos`` (numbers, text, or at top level a cell of those):
    every subelement present, of its type and of the size its dimensions say, nothing after
    them, within ``limits``; the position after the array."""
    kind, start, nbytes, after = _mat_tag(data, pos, order, end)
    if kind != _MI_MATRIX:  # 15 (compressed) included
        raise ValueError(f"MAT element of type {kind} at byte {pos}; sysid writes uncompressed "
                         "arrays only")
    if nbytes % 8:  # the subelements are padded to 8 bytes: scipy and this walk agree
        raise ValueError(f"MAT array at byte {pos} declares {nbytes} bytes, not whole words")
    if nbytes == 0:
        return after
    stop = start + nbytes
    cls, shape, name, p = _header(data, start, order, stop)
    count = math.prod(shape)
    if cls in _MX_NUMBERS and max(shape) > limits.side:
        raise ValueError(f"MAT matrix {name!r} at byte {pos} is {' x '.join(map(str, shape))}"
                         f"; a sysid model has at most {limits.side} states, inputs and outputs")
    most = limits.cells if cls == _MX_CELL else limits.values
    if cls != _MX_CHAR and count > most:
        raise ValueError(f"MAT array at byte {pos} holds {count} values; a sysid model has at "
                         f"most {most}")
    if cls == _MX_CELL and not in_cell:
        for _ in range(count):
            p = _mat_array(data, p, order, end=stop, in_cell=True, limits=limits)
    elif cls == _MX_CHAR or cls in _MX_NUMBERS:
        kind, _, size, p = _mat_tag(data, p, order, stop)
        if cls == _MX_CHAR:
            low, high = _CHAR_BYTES.get(kind, (0, -1))
            fits = low * count <= size <= high * count
            if size > limits.text_bytes:
                raise ValueError(f"MAT text at byte {pos} has {size} bytes; a sysid model's "
                                 f"texts have at most {limits.text_bytes}")
        else:
            fits = kind in _NUMBER_BYTES and size == _NUMBER_BYTES[kind] * count
        if not fits:
            raise ValueError(f"MAT array at byte {pos}: {size} bytes of type {kind} for "
                             f"{count} values")
    else:
        raise ValueError(f"MAT array of class {cls} at byte {pos}; sysid writes numbers, text "
                         "and cells of text only")
    if p < stop:
        raise ValueError(f"MAT array at byte {pos} has more elements than it declares")
    return after


def check_mat(data: bytes, *, limits: Limits | None = None) -> None:
    """Refuse (``ValueError``) a MAT file that scipy would inflate or recurse through, or
    that is larger in any part than a sysid model (module docstring). Nesting is at most one
    cell deep, so this recursion is bounded too."""
    limits = limits or Limits()
    order = {b"IM": "<", b"MI": ">"}.get(data[126:128])
    if len(data) < 128 or order is None:
        raise ValueError("not a MATLAB 5 .mat file")
    # scipy takes a file with a zero in its first four bytes for MATLAB 4, whatever follows
    if 0 in data[:4] or struct.unpack_from(order + "H", data, 124)[0] != 0x0100:
        raise ValueError("not a MATLAB 5 .mat file (header)")
    pos, count = 128, 0
    while pos < len(data):
        count += 1
        if count > limits.variables:
            raise ValueError(f"MAT file with more than {limits.variables} variables; a sysid "
                             "model has about 15")
        pos = _mat_array(data, pos, order, end=len(data), in_cell=False, limits=limits)
