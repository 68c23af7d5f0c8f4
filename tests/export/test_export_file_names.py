"""``groundstation export --to csv|parquet`` on a case-insensitive file system (macOS, Windows,
a FAT card): streams whose names differ only in case (or in how an accent is encoded) each get
a file of their own, and ``metadata.json`` says which (``stream_files``)."""

from __future__ import annotations

import csv
import json
import unicodedata

import pytest
from click.testing import CliRunner

from cfsession.schema import Field, StreamSpec
from cfsession.writer import SessionWriter
from groundstation.cli import main

NAMES = ["Motors", "motors", "motors_2", "MOTORS", "BL\u00c9", "ble\u0301"]
"""``motors_2`` is a stream's own name, so ``motors`` cannot take it; ``BLÉ`` composed,
``blé`` decomposed: one name to macOS."""


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """Stream k holds the values 10k, 10k + 1, 10k + 2."""
    path = tmp_path_factory.mktemp("case") / "s.h5"
    specs = [StreamSpec(name=n, kind="log", period_s=0.01, description="",
                        fields=(Field("host_time", "<f8", "s", ""), Field("v", "<f8", "", "v")))
             for n in NAMES]
    with SessionWriter(path, streams=specs, metadata={"uri": "x"}) as w:
        for k, n in enumerate(NAMES):
            w.extend(n, [(0.01 * j, 10.0 * k + j) for j in range(3)])
    return path


def _caseless(name: str) -> str:
    return unicodedata.normalize("NFC", name).lower()


@pytest.mark.parametrize("to", ["csv", "parquet"])
def test_streams_differing_in_case_get_files_of_their_own(session, tmp_path, to):
    """``Motors`` and ``motors`` were written as ``Motors.csv`` and ``motors.csv``: one file
    on macOS or Windows, the other stream lost."""
    if to == "parquet":
        pq = pytest.importorskip("pyarrow.parquet")
    out = tmp_path / to
    res = CliRunner().invoke(main, ["export", str(session), "--to", to, "--out", str(out)])
    assert res.exit_code == 0, res.output
    names = [p.name for p in out.iterdir()]
    assert len({n.lower() for n in names}) == len(names) == len(NAMES) + 1  # metadata.json
    assert len({_caseless(n) for n in names}) == len(names)
    files = json.loads((out / "metadata.json").read_text())["stream_files"]
    assert set(files) == set(NAMES) and set(files.values()) == set(names) - {"metadata.json"}
    assert files["motors_2"] == f"motors_2.{to}"  # its own name
    kept = {n for n in NAMES if files[n] == f"{n}.{to}"}  # the first of each caseless name
    assert len(kept & {"Motors", "motors", "MOTORS"}) == len(kept & {"BL\u00c9", "ble\u0301"}) == 1
    suffixed = {files[n].removesuffix(f".{to}"): n for n in NAMES if n not in kept}
    assert {stem.rpartition("_")[0] for stem in suffixed} == set(suffixed.values())
    assert sorted(stem.rpartition("_")[2] for stem in suffixed) == ["2", "3", "4"]
    for k, name in enumerate(NAMES):  # each file holds its stream
        if to == "csv":
            with open(out / files[name], newline="", encoding="utf-8") as fh:
                rows = list(csv.reader(fh))
            assert [float(r[1]) for r in rows[1:]] == [10 * k, 10 * k + 1, 10 * k + 2]
        else:
            table = pq.read_table(out / files[name])
            assert table.schema.metadata[b"stream"].decode() == name
            assert table.column("v").to_pylist() == [10 * k, 10 * k + 1, 10 * k + 2]


FOREIGN = ["a:b", "q?", "NUL", "con.x", ".hidden", "end. ", "tab\there", "é" * 150, "a_b"]
"""Stream names HDF5 takes that Windows or a FAT card refuse as file names (or hide)."""


def test_stream_names_no_file_system_takes_are_made_safe(tmp_path):
    """A session from elsewhere may name a stream ``a:b`` or ``NUL``: on Windows or a FAT card
    the export failed on it (or wrote an alternate data stream of ``a``)."""
    path = tmp_path / "s.h5"
    specs = [StreamSpec(name=n, kind="log", period_s=0.01, description="",
                        fields=(Field("host_time", "<f8", "s", ""), Field("v", "<f8", "", "v")))
             for n in FOREIGN]
    with SessionWriter(path, streams=specs, metadata={"uri": "x"}) as w:
        for k, n in enumerate(FOREIGN):
            w.extend(n, [(0.0, float(k))])
    out = tmp_path / "csv"
    res = CliRunner().invoke(main, ["export", str(path), "--to", "csv", "--out", str(out)])
    assert res.exit_code == 0, res.output
    files = json.loads((out / "metadata.json").read_text())["stream_files"]
    assert files["a_b"] == "a_b.csv"  # a safe name keeps it; "a:b" then gets a suffix
    assert (files["a:b"], files["q?"], files["NUL"], files["con.x"]) == (
        "a_b_2.csv", "q_.csv", "NUL_.csv", "con.x_.csv")
    assert (files[".hidden"], files["end. "], files["tab\there"]) == (
        "_hidden.csv", "end.csv", "tab_here.csv")
    assert len(files["é" * 150].encode()) <= 210
    for name in files.values():
        assert not set('<>:"/\\|?*') & set(name) and not name.startswith(".")
    for k, n in enumerate(FOREIGN):  # each file holds its stream
        with open(out / files[n], newline="", encoding="utf-8") as fh:
            assert float(list(csv.reader(fh))[1][1]) == k
