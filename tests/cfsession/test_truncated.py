"""A session file whose tail is cut off (a copy interrupted, a card pulled) reads as far as it
goes: every row stored before the cut, none of the zeros the missing bytes stand for, and the
cut named once in ``problems``; a cut inside the superblock or the root group is one line."""

from __future__ import annotations

import logging
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from cfsession import SessionWriter, open_session, standard_streams
from cfsession.errors import SessionError
from cfsession.guard import MAX_CUT_RATIO, lookup3, open_untrusted
from cfsession.schema import log_block_spec
from groundstation.cli import main as gs

N = 1500


def _write_live(path: Path, copy: Path) -> None:
    """A flight as the writer lays it out while flying (two log streams interleaved, setpoints,
    events, a flush every second of rows), copied while still open, then closed uncompressed."""
    specs = [log_block_spec(name=n, variables=[(f"{n}.{a}", "float") for a in "xyz"],
                            period_s=0.02) for n in ("acc", "gyro")]
    w = SessionWriter(path, streams=[*specs, *standard_streams()],
                      metadata={"uri": "test://cut", "plan_text": "x" * 2000},
                      flush_interval=1e9, fsync_interval=1e9, compress_on_close=False)
    w.phase(t=0.0, phase_id=0, name="excite", kind="excitation")
    for k in range(N):
        t = 0.02 * k
        w.append("acc", (t + 0.001, k, 1.0, float(k), 2.0))
        w.append("gyro", (t + 0.002, k, 3.0, float(k), 4.0))
        if k % 5 == 0:
            w.append("setpoints", (t, 0.0, 0.0, 0.0, 30000, 0, k // 5))
        if k % 100 == 0:
            w.event(t=t, text=f"event {k}")
        if k % 50 == 49:
            w.flush()
    shutil.copy(path, copy)  # as a writer killed now leaves it: flags set, uncompressed
    w.close(duration_s=N * 0.02)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("truncated")
    _write_live(d / "closed.h5", d / "open.h5")
    return {"open": d / "open.h5", "closed": d / "closed.h5", "dir": d}


def _cut(src: Path, fraction: float, dst: Path) -> int:
    data = src.read_bytes()
    keep = int(len(data) * (1 - fraction))
    dst.write_bytes(data[:keep])
    return keep


def _assert_only_stored_rows(cut_session, whole_session) -> dict[str, int]:
    """Every stream read from the cut file is a prefix of the whole file's: nothing invented
    (the zero padding read as rows), nothing reordered. Returns the rows kept per stream."""
    kept = {}
    for name, stream in cut_session.streams.items():
        got, full = stream.data, whole_session[name].data
        assert got.dtype == full.dtype
        assert got.tobytes() == full[:len(got)].tobytes(), name
        if len(got):
            assert not (got["host_time"] == 0).all() or len(got) == 1
        kept[name] = len(got)
    return kept


@pytest.mark.parametrize("fraction", [0.001, 0.01, 0.05, 0.3])
def test_a_file_cut_short_reads_every_row_before_the_cut(files, fraction, tmp_path):
    whole = open_session(files["open"])
    path = tmp_path / "cut.h5"
    keep = _cut(files["open"], fraction, path)
    s = open_session(path)
    size = files["open"].stat().st_size
    assert s.problems[0].startswith(f"file truncated at {keep} of {size} bytes")
    assert sum("truncated at" in p for p in s.problems) == 1
    assert s.problems[-1].startswith("writer did not close the file")  # and it was flagged
    kept = _assert_only_stored_rows(s, whole)
    assert s.meta["uri"] == "test://cut"  # a flying writer's root attributes come first
    for name in ("acc", "gyro"):
        if name not in kept:  # its chunk index lay beyond the cut: that stream's problem
            assert any(p.startswith(f"stream {name!r}: unreadable (") and
                       p.endswith("its metadata lay beyond the cut)") for p in s.problems)
            continue
        lost = len(whole[name]) - kept[name]
        said = [p for p in s.problems if p.startswith(f"stream {name!r}: unreadable from row")]
        if lost:
            assert said == [f"stream {name!r}: unreadable from row {kept[name]} ({lost} rows "
                            "lay beyond the cut)"]
        else:
            assert not said
    if fraction == 0.05:
        assert 0 < kept["acc"] < N and 0 < kept["gyro"] < N
    if fraction <= 0.05:
        # rows lying wholly before the cut are kept: at most the chunks the cut crossed and
        # those after it are lost (rows of 28 bytes, both streams' chunks beyond the cut)
        assert kept["acc"] + kept["gyro"] >= 2 * N - (size - keep) // 28 - 2 * 50


def test_its_copy_has_the_same_rows_whatever_the_fraction_left(files, tmp_path):
    """More cut, never more rows; a cut deep into the file is still a read or one line."""
    whole = open_session(files["open"])
    before = None
    for fraction in (0.0005, 0.02, 0.1, 0.5, 0.9):
        path = tmp_path / f"cut-{fraction}.h5"
        _cut(files["open"], fraction, path)
        try:
            s = open_session(path)
        except SessionError as exc:
            assert "damaged beyond repair (truncated at" in str(exc)
            assert "\n" not in str(exc)
            continue
        rows = sum(_assert_only_stored_rows(s, whole).values())
        assert before is None or rows <= before
        before = rows


@pytest.mark.parametrize("fraction", [0.01, 0.05, 0.3, 0.5])
def test_a_closed_file_cut_short_loses_its_root_attributes_not_its_streams(files, fraction,
                                                                          tmp_path):
    """A closed file's root attributes were rewritten at its end: a cut of 1 % loses them
    (uri, schema, summary); its streams are still read, the loss said once."""
    whole = open_session(files["closed"])
    path = tmp_path / "cut.h5"
    _cut(files["closed"], fraction, path)
    s = open_session(path)
    assert s.problems[0].startswith("file truncated at")
    _assert_only_stored_rows(s, whole)
    assert s.streams
    if "uri" not in s.meta:
        assert any(p.startswith(("root attributes unreadable", f"{path}: attribute"))
                   for p in s.problems)
    assert not any("writer did not close" in p for p in s.problems)  # its superblock is clean


def test_metadata_beyond_the_cut_is_that_streams_problem(files, tmp_path):
    whole = open_session(files["closed"])
    path = tmp_path / "cut.h5"
    _cut(files["closed"], 0.3, path)
    s = open_session(path)
    gone = [p for p in s.problems if "its metadata lay beyond the cut" in p]
    assert gone, s.problems
    for line in gone:
        name = line.split("'")[1]
        assert name in whole.streams and name not in s.streams


def test_info_lists_the_cut_and_exits_0(files, tmp_path):
    path = tmp_path / "cut.h5"
    keep = _cut(files["open"], 0.05, path)
    res = CliRunner().invoke(gs, ["info", str(path), "--width", "200"])
    assert res.exit_code == 0, res.output
    assert f"truncated at {keep} of {files['open'].stat().st_size} bytes" in res.output
    assert "'acc': unreadable from row" in res.output


@pytest.mark.parametrize("keep", [30, 100, 600])
def test_a_cut_inside_the_superblock_or_root_group_is_one_line(files, keep, tmp_path):
    path = tmp_path / "cut.h5"
    path.write_bytes(files["open"].read_bytes()[:keep])
    res = CliRunner().invoke(gs, ["info", str(path)])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "damaged beyond repair (truncated at" in res.output
    with pytest.raises(SessionError, match=r"damaged beyond repair \(truncated at"):
        open_session(path)


def _claim_end(path: Path, eof: int) -> None:
    raw = bytearray(path.read_bytes())
    raw[28:36] = eof.to_bytes(8, "little")
    raw[44:48] = lookup3(bytes(raw[:44])).to_bytes(4, "little")
    path.write_bytes(bytes(raw))


def test_an_absurd_stored_end_is_refused_not_padded(files, tmp_path):
    path = tmp_path / "cut.h5"
    keep = _cut(files["open"], 0.5, path)
    _claim_end(path, MAX_CUT_RATIO * keep + (1 << 20) + 1)
    with pytest.raises(SessionError, match=r"truncated at .* no file cut short"):
        open_session(path)
    _claim_end(path, 1 << 62)
    with pytest.raises(SessionError, match=r"damaged beyond repair|more than"):
        open_session(path)
    raw = bytearray(files["open"].read_bytes()[:keep])
    raw[31] ^= 1  # the stored end 16 MiB more, its checksum not matching
    path.write_bytes(bytes(raw))
    with pytest.raises(SessionError, match="checksum does not match"):
        open_session(path)


def test_model_files_cut_short_are_still_refused(files, tmp_path):
    """Only the session reader, which knows which chunks lay beyond the cut, reads them:
    :func:`open_untrusted` (sysid model files) refuses a cut file as before."""
    path = tmp_path / "cut.h5"
    _cut(files["closed"], 0.01, path)
    with pytest.raises(SessionError, match=r"damaged beyond repair \(truncated at \d+ of"):
        open_untrusted(path)


def test_the_file_on_disk_is_not_changed(files, tmp_path):
    path = tmp_path / "cut.h5"
    _cut(files["open"], 0.05, path)
    before = path.read_bytes()
    open_session(path)
    assert path.read_bytes() == before
    with pytest.raises(OSError, match="truncated file"):  # HDF5 itself still refuses it
        h5py.File(path, "r", locking=False)


# ---------------------------------------------------------------------- sysid reads it


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    from tests.sysid.flights import known_system, write_flight

    d = tmp_path_factory.mktemp("truncated-flight")
    good = write_flight(d / "good.h5", system=known_system(), seed=8, n=1500).path
    return good


@pytest.mark.parametrize("fraction", [0.002, 0.02, 0.1])
def test_a_flight_saved_compressed_loses_the_end_of_the_flight_only(flight, fraction, tmp_path):
    """A flight's file as saved at landing (``compressed_image``): metadata first, then the rows
    in time order across streams. A cut loses the last stretch of the flight in every stream,
    about as much as was cut, never a whole stream, the root attributes or the phases."""
    whole = open_session(flight)
    path = tmp_path / "cut.h5"
    _cut(flight, fraction, path)
    s = open_session(path)
    kept = _assert_only_stored_rows(s, whole)
    assert s.meta == whole.meta
    assert kept["phases"] == len(whole["phases"].data) > 0
    assert set(s.streams) == set(whole.streams)
    for name, stream in whole.streams.items():
        n = len(stream.data)
        if n >= 200:
            lost = 1 - kept[name] / n
            assert lost <= 2 * fraction + 0.03, (name, lost)
    ends = [s[n].data["host_time"][-1] for n in ("motors", "acc", "gyro")]
    assert max(ends) - min(ends) < 0.1 * (whole["motors"].data["host_time"][-1])


def test_sysid_identifies_a_truncated_flight_and_warns(flight, tmp_path, caplog):
    """A flight cut by 2 % lost its last rows, not its phases: identified with the automatic
    window, each problem a warning; the samples it has are the whole file's."""
    from sysid.cli import main as sysid_main
    from sysid.session_io import load_experiments

    path = tmp_path / "cut.h5"
    _cut(flight, 0.02, path)
    problems = open_session(path).problems
    assert problems[0].startswith("file truncated at")
    assert any("rows lay beyond the cut" in p for p in problems)
    with caplog.at_level(logging.WARNING, logger="sysid.session_io"):
        data = load_experiments(path)
    warned = [r.getMessage() for r in caplog.records if ": problem: " in r.getMessage()]
    assert warned == [f"{path}: problem: {p}" for p in problems]
    whole = load_experiments(flight)
    assert len(data) == len(whole)
    n = len(data[0].y)
    assert 0.9 * len(whole[0].y) < n < len(whole[0].y)
    offset = data[0].y - whole[0].y[:n]  # the same samples, their means taken over fewer
    np.testing.assert_allclose(offset, offset[:1].repeat(n, axis=0), atol=1e-9)
    fast = ["--order", "4", "--past", "20", "--future", "10"]
    res = CliRunner().invoke(sysid_main, ["identify", str(path), *fast])
    assert res.exit_code == 0, res.output
    assert "identified from" in res.stdout
