"""sysid/model_io.py, JSON model files crafted to break the reader: one ModelFileError line from
the library and one ``error:`` line (exit 2) from the CLI.

Known truth: what each crafted file was made to do (an unknown or missing version, text, ragged
or deep tables, huge integers, a million empty lists, NaN, the wrong shapes), JSON nested deeper
than Python parses, bytes that are not text, and a file one byte over ``MAX_FILE_BYTES``.
"""
from __future__ import annotations

import json
from collections.abc import Callable

import pytest

from sysid import model_io
from sysid.model_io import save
from tests.sysid.model_files import refused, sample_model


def _json_edit(**changes: object) -> Callable[[dict], object]:
    def edit(d: dict) -> dict:
        for k, v in changes.items():
            if v is None:
                d.pop(k)
            else:
                d[k] = v
        return d
    return edit


JSON_CASES = {
    "no version": (_json_edit(version=None), "no format version"),
    "version null": (lambda d: {**d, "version": None}, "no format version"),
    "version 0": (_json_edit(version=0), "format version 0;"),
    "version text": (_json_edit(version="1"), "format version '1';"),
    "version true": (_json_edit(version=True), "format version True;"),
    "newer version": (_json_edit(version=7), "version 7 is newer than 1"),
    "no D": (_json_edit(D=None), r"\(no D\)"),
    "text in A": (_json_edit(A=[["0.9", "0.1"], ["0", "0.7"]]), "'A' holds text"),
    "ragged A": (_json_edit(A=[[0.9, 0.1], [0.7]]), "'A' is not a table of numbers"),
    "deep A": (_json_edit(A=json.loads("[" * 100 + "1" + "]" * 100)), "'A' is not a table"),
    "huge integer": (_json_edit(D=[[10**30]]), "'D' holds objects"),
    "booleans": (_json_edit(D=[[True]]), "'D' holds true/false"),
    # 3 MB of "[]," would take about 60 MB as Python objects (120 MB: 2.5 GB)
    "a million empty lists": (_json_edit(provenance={"x": [[]] * 1_000_001}),
                              r"\d{7} JSON arrays and objects, more than a model has \(1000000\)"),
    "NaN": (_json_edit(K=[[float("nan")], [0.0]]), "'K' contains NaN or inf"),
    "C of the wrong shape": (_json_edit(C=[[1.0, 0.0, 0.0]]),
                             r"matrix 'C' has shape \(1, 3\); it must be \(l, n\) = \(1, 2\)"),
    "a vector for B": (_json_edit(B=[1.0, 0.5]), r"'B' has shape \(2,\)"),
    "dt zero": (_json_edit(dt=0), "dt is 0"),
    "units not text": (_json_edit(input_units=[1]), "input_units is .*not a list of text"),
    "not a dict": (lambda d: [d], "not a sysid model file"),
}


@pytest.mark.parametrize("case", list(JSON_CASES))
def test_crafted_json_model_is_one_line(tmp_path, case):
    edit, match = JSON_CASES[case]
    path = tmp_path / "m.json"
    path.write_text(json.dumps(edit(sample_model().to_dict())))
    refused(path, match)


def test_json_deeper_than_python_parses_or_larger_than_the_cap(tmp_path, monkeypatch):
    path = tmp_path / "m.json"
    path.write_text("[" * 1_000_000 + "]" * 1_000_000)
    refused(path, "not a readable sysid model")
    path.write_bytes(b"\xff\xfe\x00" * 10)
    refused(path, "not a readable sysid model")
    save(sample_model(), path)
    monkeypatch.setattr(model_io, "MAX_FILE_BYTES", path.stat().st_size - 1)
    refused(path, f"larger than {path.stat().st_size - 1} bytes")


