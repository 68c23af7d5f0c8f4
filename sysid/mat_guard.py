"""The shape of a MATLAB 5 ``.mat`` file checked before scipy reads it (model files are untrusted).

scipy's ``loadmat`` inflates compressed elements (one may grow a thousandfold) and recurses in C
through nested cells (9 MB of them crashed the interpreter). :func:`check_mat` walks the element
tags in Python first and lets through only what :func:`sysid.model_io.save` writes: MATLAB 5,
uncompressed arrays of numbers or text, and at top level cells of those. Every element must
fit inside its parent; anything else is a ``ValueError`` naming the byte where it is.
"""

from __future__ import annotations

import struct

__all__ = ["check_mat"]

# MAT-file element types and array classes (MATLAB 5 format): what check_mat lets through
_MI_UINT32, _MI_MATRIX = 6, 14
_MX_CELL, _MX_CHAR = 1, 4
_MX_NUMBERS = range(6, 16)  # double, single, int8 ... uint64


def _mat_tag(data: bytes, pos: int, order: str, end: int) -> tuple[int, int, int, int]:
    """``(type, payload start, payload bytes, next position)`` of the MAT element at ``pos``."""
    if pos + 8 > end:
        raise ValueError(f"MAT element at byte {pos} is cut off")
    word, nbytes = struct.unpack_from(order + "II", data, pos)
    if word >> 16:  # small data element: type and size in one word, data in the next four
        return word & 0xFFFF, pos + 4, word >> 16, pos + 8
    after = pos + 8 + nbytes + (-nbytes % 8)
    if pos + 8 + nbytes > end:
        raise ValueError(f"MAT element at byte {pos} declares {nbytes} bytes past the end")
    return word, pos + 8, nbytes, min(after, end)


def _mat_array(data: bytes, pos: int, order: str, *, end: int, in_cell: bool) -> int:
    """Check the array element at ``pos`` (numbers, text, or at top level a cell of those);
    the position after it."""
    kind, start, nbytes, after = _mat_tag(data, pos, order, end)
    if kind != _MI_MATRIX:  # 15 (compressed) included
        raise ValueError(f"MAT element of type {kind} at byte {pos}; sysid writes uncompressed "
                         "arrays only")
    if nbytes == 0:
        return after
    kind, flags, size, p = _mat_tag(data, start, order, start + nbytes)
    if kind != _MI_UINT32 or size < 4:
        raise ValueError(f"MAT array at byte {pos} has no array flags")
    cls = struct.unpack_from(order + "I", data, flags)[0] & 0xFF
    if not (cls == _MX_CHAR or cls in _MX_NUMBERS or (cls == _MX_CELL and not in_cell)):
        raise ValueError(f"MAT array of class {cls} at byte {pos}; sysid writes numbers, text "
                         "and cells of text only")
    if cls == _MX_CELL:
        for _ in range(2):  # dimensions, name
            p = _mat_tag(data, p, order, start + nbytes)[3]
        while p < start + nbytes:
            p = _mat_array(data, p, order, end=start + nbytes, in_cell=True)
    return after


def check_mat(data: bytes) -> None:
    """Refuse (``ValueError``) a MAT file that scipy would inflate or recurse through (module
    docstring). Nesting is at most one cell deep, so this recursion is bounded too."""
    order = {b"IM": "<", b"MI": ">"}.get(data[126:128])
    if len(data) < 128 or order is None:
        raise ValueError("not a MATLAB 5 .mat file")
    pos = 128
    while pos < len(data):
        pos = _mat_array(data, pos, order, end=len(data), in_cell=False)
