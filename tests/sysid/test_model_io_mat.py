"""sysid/model_io.py, MAT model files crafted to break the reader (built byte by byte where
scipy would not write them): one ModelFileError line from the library and one ``error:`` line
(exit 2) from the CLI; a version MATLAB saved as a double is read.

Known truth: what each crafted file was made to do (compression, cells, structs, complex
numbers, an HDF5 file under a .mat name, dimensions, cells, texts and variable counts sized to
cost time or memory, sizes that are not whole words, flags and dimensions that lie), and
scipy's own crash on nested MAT cells.
"""
from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from sysid.model_io import load, save
from tests.sysid.model_files import refused, sample_model


def _mat_element(cls: int, name: str, body: bytes, dims: tuple[int, ...] = (1, 1)) -> bytes:
    """One uncompressed MATLAB 5 array element of class ``cls`` (``dims``) holding ``body``."""
    text = name.encode()
    shape = struct.pack(f"<{len(dims)}i", *dims).ljust(-(-4 * len(dims) // 8) * 8, b"\0")
    parts = (struct.pack("<IIII", 6, 8, cls, 0) + struct.pack("<II", 5, 4 * len(dims)) + shape +
             struct.pack("<II", 1, len(text)) + text.ljust(-(-len(text) // 8) * 8, b"\0") + body)
    return struct.pack("<II", 14, len(parts)) + parts


def _mat_file(*elements: bytes, first: bytes = b"MATLAB 5.0 MAT-file") -> bytes:
    return first.ljust(116) + bytes(8) + struct.pack("<H", 0x0100) + b"IM" + b"".join(elements)


_DOUBLE_1 = struct.pack("<II", 9, 8) + struct.pack("<d", 1.0)


def _nested_cells(depth: int) -> bytes:
    """A MAT file whose variable A is ``depth`` cells in cells around one number: scipy's reader
    recurses in C for each level, and some 200 000 levels (9 MB) crash the interpreter."""
    inner = _mat_element(6, "", struct.pack("<II", 9, 8) + struct.pack("<d", 1.0))
    for level in range(depth):
        inner = _mat_element(1, "A" if level == depth - 1 else "", inner)
    return _mat_file(inner)


def _mat_vars(path: Path) -> dict[str, object]:
    return {k: v for k, v in scipy.io.loadmat(path).items() if not k.startswith("__")}


def _mat_flip(path: Path, *, offset: int, value: int) -> None:
    """Set byte ``offset`` of the first array's payload (byte 136 of the file) to ``value``:
    9 is the array flags' second byte (complex 0x08, global 0x04, logical 0x02), 24 the low
    byte of its first dimension."""
    data = bytearray(path.read_bytes())
    data[136 + offset] = value
    path.write_bytes(bytes(data))


def _mat_edit(**changes: object) -> Callable[[Path], None]:
    def edit(path: Path) -> None:
        m = _mat_vars(path)
        for k, v in changes.items():
            if v is None:
                m.pop(k)
            else:
                m[k] = v
        scipy.io.savemat(path, m)
    return edit


MAT_CASES = {
    "compressed": (lambda p: scipy.io.savemat(p, _mat_vars(p), do_compression=True),
                   "uncompressed arrays only"),
    "cells in cells": (lambda p: p.write_bytes(_nested_cells(3)), "MAT array of class 1"),
    "a struct": (_mat_edit(provenance={"method": "iem"}), "MAT array of class 2"),
    "HDF5 (MATLAB 7.3)": (lambda p: p.write_bytes((p.parent / "m.h5").read_bytes()),
                          "not a MATLAB 5 .mat file"),
    "complex": (_mat_edit(A=np.eye(2) * 1j), r"MAT array at byte \d+ is complex"),
    # crafted to cost time or memory (a helper's structural fuzzing): each was seconds and GB
    "150 001 dimensions": (lambda p: p.write_bytes(_mat_file(_mat_element(
        6, "A", _DOUBLE_1, dims=(2**31 - 1,) * 150_000 + (0,)))), "has 150001 dimensions"),
    "a cell of 5 million": (lambda p: p.write_bytes(_mat_file(_mat_element(
        1, "InputName", b"", dims=(1, 5_000_000)))), "holds 5000000 values; .* at most 500"),
    "a 2 MB text": (lambda p: p.write_bytes(_mat_file(_mat_element(
        4, "provenance", struct.pack("<II", 16, 2 << 20) + b"[" * (2 << 20),
        dims=(1, 2 << 20)))), r"MAT text at byte 128 has 2097152 bytes"),
    "MATLAB 4 behind a 5 header": (lambda p: p.write_bytes(_mat_file(
        _mat_element(6, "A", _DOUBLE_1), first=b"\0ATLAB 5.0")), r"not a MATLAB 5 \.mat file"),
    "65 variables": (lambda p: p.write_bytes(_mat_file(*(
        _mat_element(6, f"v{i}", _DOUBLE_1) for i in range(65)))), "more than 64 variables"),
    "an odd size": (lambda p: p.write_bytes(_mat_file(
        _mat_element(6, "A", _DOUBLE_1)[:4] + struct.pack("<I", 49) +
        _mat_element(6, "A", _DOUBLE_1)[8:] + bytes(8))), "declares 49 bytes, not whole words"),
    # the complex bit set on a real array (no imaginary part): scipy's reader segfaulted
    "complex flag, no imaginary part": (lambda p: _mat_flip(p, offset=9, value=0x08),
                                        r"MAT array at byte 136 is complex"),
    "fewer numbers than its dimensions": (lambda p: _mat_flip(p, offset=24, value=9),
                                          r"MAT array at byte 128: \d+ bytes of type \d+ for"),
    "text A": (_mat_edit(A="abcd"), "'A' holds text"),
    "no version": (_mat_edit(version=None), "no format version"),
    "version 2": (_mat_edit(version=2), "version 2 is newer than 1"),
    "version 1.5": (_mat_edit(version=1.5), "format version 1.5;"),
    "no K": (_mat_edit(K=None), r"\(no K\)"),
    "names as numbers": (_mat_edit(InputName=np.array([[1.0]])), "input_names is"),
    "D of the wrong shape": (_mat_edit(D=np.ones((2, 2))),
                             r"matrix 'D' has shape \(2, 2\); it must be \(l, m\) = \(1, 1\)"),
    "inf": (_mat_edit(B=np.array([[np.inf], [0.0]])), "'B' contains NaN or inf"),
}


@pytest.mark.timeout(60)
@pytest.mark.parametrize("case", list(MAT_CASES))
def test_crafted_mat_model_is_one_line(tmp_path, case):
    edit, match = MAT_CASES[case]
    save(sample_model(), tmp_path / "m.h5")
    path = save(sample_model(), tmp_path / "m.mat")
    edit(path)
    refused(path, match)


def test_mat_version_saved_by_matlab_as_a_double_is_read(tmp_path):
    path = save(sample_model(), tmp_path / "m.mat")
    _mat_edit(version=np.array([[1.0]]))(path)
    assert load(path).K.tolist() == sample_model().K.tolist()
