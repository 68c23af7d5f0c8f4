"""Session files from elsewhere: crafted ones are refused in one line, damaged ones never hang.

Known truth: what each crafted file was made to do (read another file, follow a link, declare
rows it does not store), and HDF5's own endless loop on a global heap object of size 0 (seen
in the fuzz campaign: a flipped byte in a killed writer's file hung ``info`` for ever).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from cfsession import open_session
from cfsession.errors import SessionError
from cfsession.schema import log_block_spec
from cfsession.writer import SessionWriter, standard_streams
from groundstation.cli import main

from .hostile import declare_text_length, mark_killed


def _write(path, *, close: bool = True, compress: bool = False, metadata=None):
    gyro = log_block_spec(name="gyro", variables=[("gyro.x", "float")], period_s=0.02)
    w = SessionWriter(path, streams=[gyro, *standard_streams()],
                      metadata=metadata or {"uri": "sim://0"}, compress_on_close=compress)
    for k in range(100):
        w.append("gyro", (k * 0.02, 20 * k, float(k)))
    w.event(t=0.0, text="hello")
    w.flush(fsync=True)
    if close:
        w.close(summary={"ok": 1})
    return w


@pytest.fixture
def session(tmp_path):
    path = tmp_path / "s.h5"
    _write(path)
    return path


def _refused(path, match: str) -> str:
    with pytest.raises(SessionError, match=match) as info:
        open_session(path)
    msg = str(info.value)
    assert "\n" not in msg and str(path) in msg
    result = CliRunner().invoke(main, ["info", str(path)])
    assert result.exit_code == 2 and result.output.strip().count("\n") == 0, result.output
    return msg


def test_external_storage_is_refused_not_read(session, tmp_path):
    secret = tmp_path / "passwd"
    secret.write_bytes(b"root:x:0:0:root:/root:/bin/bash\n" * 4)
    with h5py.File(session, "a") as f:
        dt = f["gyro/data"].dtype
        del f["gyro/data"]
        f["gyro"].create_dataset("data", shape=(4,), dtype=dt,
                                 external=[(str(secret), 0, h5py.h5f.UNLIMITED)])
    assert "passwd" in _refused(session, "data stored outside the file")


def test_external_storage_on_a_fifo_is_refused_at_once(session, tmp_path):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)  # reading it would block for ever
    with h5py.File(session, "a") as f:
        dt = f["events/data"].dtype
        del f["events/data"]
        f["events"].create_dataset("data", shape=(4,), dtype=dt,
                                   external=[(str(fifo), 0, h5py.h5f.UNLIMITED)])
    _refused(session, "data stored outside the file")


def test_a_fifo_as_the_session_path_is_refused(tmp_path):
    fifo = tmp_path / "s.h5"
    os.mkfifo(fifo)
    _refused(fifo, "not a regular file")


@pytest.mark.parametrize("link", ["external", "soft", "loop"])
def test_links_are_not_followed(session, tmp_path, link):
    other = tmp_path / "other.h5"
    _write(other)
    with h5py.File(session, "a") as f:
        if link == "external":
            f["stolen"] = h5py.ExternalLink(str(other), "/gyro")
        elif link == "soft":
            f["alias"] = h5py.SoftLink("/gyro")
        else:
            f["gyro"]["loop"] = h5py.SoftLink("/gyro/loop")
    _refused(session, "links to another file" if link == "external" else "soft link")


def test_virtual_dataset_is_refused(session, tmp_path):
    other = tmp_path / "other.h5"
    _write(other)
    with h5py.File(session, "a") as f:
        dt = f["gyro/data"].dtype
        layout = h5py.VirtualLayout(shape=(10,), dtype=dt)
        layout[:] = h5py.VirtualSource(str(other), "gyro/data", shape=(10,))
        del f["gyro/data"]
        f["gyro"].create_virtual_dataset("data", layout)
    _refused(session, "virtual dataset")


@pytest.mark.parametrize("rows", [2**28, 2**40])
def test_declared_rows_the_file_cannot_hold_are_refused(session, rows):
    with h5py.File(session, "a") as f:
        dt = f["gyro/data"].dtype
        del f["gyro/data"]
        f["gyro"].create_dataset("data", shape=(rows,), maxshape=(None,), dtype=dt,
                                 chunks=(64,))
    _refused(session, f"declares {rows} rows")


@pytest.mark.parametrize("data", [
    np.arange(5.0),  # not rows of fields
    np.zeros(3, dtype=[("host_time", "S8"), ("level", "u1")]),  # text time
    np.array([(0.0, "x")], dtype=[("host_time", "f8"), ("text", h5py.string_dtype())]),
])
def test_wrong_dtypes_are_refused(session, data):
    with h5py.File(session, "a") as f:
        del f["events/data"]
        f["events"].create_dataset("data", data=data)
    _refused(session, "stream 'events'")


def test_a_standard_stream_lacking_fields_is_left_out(session):
    with h5py.File(session, "a") as f:
        del f["events/data"]
        f["events"].create_dataset("data", data=np.zeros(3, dtype=[("host_time", "f8"),
                                                                   ("level", "u1")]))
    s = open_session(session)
    assert "events" not in s.streams and len(s["gyro"].data) == 100
    assert s.problems == ["stream 'events': not read: it lacks field(s) ['source', 'text', 'cont']"]


@pytest.mark.parametrize("version", [-1, 0, 2, 1.5, "1", [1, 1]])
def test_schema_version_is_checked(session, version):
    with h5py.File(session, "a") as f:
        f.attrs["schema_version"] = version
    _refused(session, "schema")


def test_deep_json_and_wrongly_typed_attributes_are_ignored(session):
    with h5py.File(session, "a") as f:
        f.attrs["summary"] = "[" * 100_000 + "]" * 100_000
        f.attrs["closed_cleanly"] = np.array([1, 1])
        f["gyro"].attrs["period_s"] = "fast"
        f["gyro/data"].attrs["units"] = 7
    s = open_session(session)
    assert s.json_meta("summary", {}) == {}
    assert s["gyro"].period_s is None and s["gyro"].units == {"host_time": "",
                                                              "fw_time_ms": "", "x": ""}
    assert len(s["gyro"]) == 100 and not s.closed_cleanly
    assert any("closed_cleanly" in p for p in s.problems)
    result = CliRunner().invoke(main, ["info", str(session)])
    assert result.exit_code == 0, result.output


def test_attributes_that_are_not_numbers_or_text_are_skipped_unread(session):
    """A sequence, a compound and an enum where the schema has numbers or text: skipped and
    listed as problems (a damaged string type read as a sequence crashed HDF5); the rest of
    the session reads as usual."""
    with h5py.File(session, "a") as f:
        seq = np.empty(1, dtype=object)
        seq[0] = np.arange(3, dtype=np.int32)
        f["gyro"].attrs.create("description", data=seq, dtype=h5py.vlen_dtype(np.int32))
        f["gyro"].attrs["period_s"] = np.zeros(1, dtype=[("a", "f8"), ("b", "i4")])
        f["gyro/data"].attrs.create("units", data=np.array([0, 2], dtype=np.int8),
                                    dtype=h5py.enum_dtype({"a": 0, "b": 1, "c": 2}, basetype="i1"))
        f["gyro"].attrs["flag"] = True  # h5py's boolean enum: read as it is
    s = open_session(session)
    skipped = [p for p in s.problems if "skipped (HDF5 type class" in p]
    assert len(skipped) == 3, s.problems
    assert s["gyro"].attrs["flag"] == True  # noqa: E712 (a numpy bool)
    for kind in ("variable-length sequence", "compound", "enum"):
        assert any(kind in p for p in skipped), (kind, skipped)
    assert s["gyro"].period_s is None and len(s["gyro"]) == 100
    result = CliRunner().invoke(main, ["info", str(session)])
    assert result.exit_code == 0, result.output


def test_killed_writer_file_is_read_without_changing_it(tmp_path):
    path = tmp_path / "killed.h5"
    w = _write(path, close=False)
    before = path.read_bytes()
    assert before[11] != 0  # superblock: still open for (SWMR) writing
    s = open_session(path)
    assert not s.closed_cleanly and len(s["gyro"]) == 100 and s.events()[0].text == "hello"
    assert path.read_bytes() == before
    w.close()


def test_a_global_heap_that_hdf5_would_walk_for_ever_is_refused(tmp_path):
    """A killed writer's file whose text heap says "free space of 0 bytes": HDF5 2.0 loops on
    it for ever. Checked in a child process, so a regression fails rather than hangs."""
    path = tmp_path / "killed.h5"
    w = _write(path, close=False)
    data = bytearray(path.read_bytes())
    w.close()
    at = data.find(b"GCOL")
    p = at + 16  # first object: walk to the free-space object (index 0) and empty it
    while int.from_bytes(data[p:p + 2], "little") != 0:
        size = int.from_bytes(data[p + 8:p + 16], "little")
        p += 16 + (size + 7) // 8 * 8
    data[p + 8:p + 16] = bytes(8)
    path.write_bytes(bytes(data))
    code = textwrap.dedent(f"""
        from cfsession.errors import SessionError
        from cfsession import open_session
        try:
            open_session({str(path)!r})
        except SessionError as exc:
            print(exc)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=60)
    assert "would be read for ever" in out.stdout, out


def test_the_heap_check_reads_a_file_cut_short_while_it_is_read(tmp_path):
    """The text-heap check reads the file in pieces by offset: a file cut short after it was
    opened (a copy being replaced, a disk filling) reads short. It was a memory map, which kills
    the process (SIGBUS) on a page beyond the new end. The same file whole is checked as
    before: a heap walked for ever is found in pieces too."""
    from cfsession.guard import _heap_loop
    from cfsession.vlen_text import FileBytes

    path = tmp_path / "s.h5"
    _write(path)
    data = path.read_bytes()
    at = data.find(b"GCOL")
    assert at > 0
    with FileBytes(path=path) as raw:
        with open(path, "r+b") as fh:
            fh.truncate(at + 24)  # inside the heap collection's first object
        assert raw.size == len(data) and _heap_loop(raw) is None
    looped = bytearray(data)
    looped[at + 16:at + 18] = bytes(2)  # the first object made free space (index 0) ...
    looped[at + 24:at + 32] = bytes(8)  # ... of 0 bytes
    assert _heap_loop(FileBytes(path=path, image=bytes(looped))) == at


# The child's peak resident memory since its exec (VmHWM: ru_maxrss would keep the pytest
# worker's peak across fork and exec, hundreds of MiB after other tests).
_READ_IN_A_CHILD = textwrap.dedent("""
    import json, sys
    def _peak_mib():
        status = open("/proc/self/status").read()
        return int(status.split("VmHWM:")[1].split()[0]) >> 10
    from cfsession import open_session
    s = open_session(sys.argv[1])
    print(json.dumps({"problems": s.problems, "meta": sorted(s.meta), "rows": len(s["gyro"]),
                      "gyro": sorted(s["gyro"].attrs), "units": s["gyro"].units,
                      "peak_mib": _peak_mib()}))
""")


@pytest.mark.parametrize("where", ["stream group", "root", "root beside a huge attribute",
                                   "killed writer's root"])
def test_text_declaring_a_gigabyte_is_skipped_unread(tmp_path, where):
    """A text attribute whose one value (16 bytes stored) declares 1 GiB for a 40-byte heap
    object: HDF5 allocated and cleared the declared length before failing (measured for 3.75
    GiB: 3.9 GB peak, 11 s). Now skipped and listed, unread, wherever the file keeps it: a
    stream's object header, the root's many-attribute heap (its blocks, or the whole file when
    that heap holds a huge attribute), the private copy of a file whose writer died. The rest
    reads as usual. Read in a child process, whose peak memory is the measure (no timing)."""
    path = tmp_path / "s.h5"
    _write(path)
    text = b"Q" * 40
    with h5py.File(path, "a") as f:
        if "huge" in where:
            f.attrs["table"] = np.arange(5000.0)  # 40 kB: stored apart, as a huge heap object
        (f["gyro"] if where == "stream group" else f).attrs["note"] = text.decode()
        meta, gyro = sorted(f.attrs), sorted(f["gyro"].attrs)
    declare_text_length(path, text, 1 << 30)
    if "killed" in where:
        mark_killed(path)
    out = subprocess.run([sys.executable, "-c", _READ_IN_A_CHILD, str(path)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout)
    skipped = [p for p in got["problems"] if "'note'" in p]
    assert len(skipped) == 1 and skipped[0].startswith(str(path)), got["problems"]
    assert skipped[0].endswith("attribute 'note' skipped (variable-length text of 1073741824 "
                               "declared bytes)"), skipped
    assert got["peak_mib"] < 300, got["peak_mib"]  # about 50 MiB; 1 GiB and more before
    assert len(got["problems"]) == 1 + ("killed" in where), got["problems"]
    assert set(got["meta"]) == set(meta) - {"note"} and set(got["gyro"]) == set(gyro) - {"note"}
    assert got["rows"] == 100 and got["units"]["x"] == "deg/s"  # a list of texts, read


@pytest.mark.parametrize("variant", ["clean", "compressed", "killed"])
def test_every_attribute_the_writer_writes_is_read(tmp_path, variant):
    """Text attributes are read after their lengths are checked in the file's bytes: every one
    the writer writes (texts, lists of texts; at the root, more than HDF5 keeps in the object
    header, and a 40 kB array stored apart) is read, equal to h5py's own reading."""
    metadata = {"uri": "sim://0", "plan_name": "prbs", "phase_table": [{"name": "hover"}],
                "trim": np.arange(5000.0), **{f"note{i}": "x" * i for i in range(20)}}
    ref = tmp_path / "ref.h5"
    _write(ref, metadata=metadata)
    with h5py.File(ref, "r") as f:
        want = {"/": dict(f.attrs), "gyro": dict(f["gyro"].attrs),
                "gyro/data": dict(f["gyro/data"].attrs)}
    path = tmp_path / "s.h5"
    w = _write(path, metadata=metadata, close=variant != "killed",
               compress=variant == "compressed")
    s = open_session(path)
    assert s.problems == ([] if variant != "killed" else [
        "writer did not close the file (crash or kill): data up to the last flush"])
    assert set(s.meta) == set(want["/"]) and set(s["gyro"].attrs) == set(want["gyro"])
    for key in ("uri", "plan_name", "phase_table", "note19", "software_version"):
        assert s.meta[key] == want["/"][key], key
    assert np.array_equal(s.meta["trim"], want["/"]["trim"])
    assert s["gyro"].attrs == {k: str(v) if isinstance(v, str) else v
                               for k, v in want["gyro"].items()}
    assert s["gyro"].sources == dict(zip(["host_time", "fw_time_ms", "x"],
                                         want["gyro/data"]["sources"], strict=True))
    w.close()


def _retyped(data, field, dtype, values):
    out = np.zeros(data.shape, dtype=[(n, dtype if n == field else data.dtype.fields[n][0])
                                      for n in data.dtype.names])
    for n in data.dtype.names:
        out[n] = values if n == field else data[n]
    return out


@pytest.mark.parametrize(("stream", "field", "dtype", "value", "holds"), [
    ("phases", "phase_id", "f8", np.nan, "integers"),  # int(NaN): ValueError in info, sysid
    ("phases", "name", "i4", 7, "text"),  # a number where text is: TypeError in info
    ("events", "level", "f8", np.nan, "integers"),
    ("events", "text", "f8", 1.0, "text"),
    ("setpoints", "roll", "S3", b"x", "numbers"),
    ("gyro", "fw_time_ms", "f8", np.nan, "integers"),  # NaN ms: garbage firmware times
])
def test_a_standard_field_of_the_wrong_type_leaves_that_stream_out(session, stream, field,
                                                                   dtype, value, holds):
    """The stream is not read (its field would crash what uses it) and the problem is listed;
    the file's other streams are read, and ``info`` shows them with the problem."""
    with h5py.File(session, "a") as f:
        if stream == "phases":
            f["phases/data"].resize((2,))
            f["phases/data"][:] = np.array([(0.0, 0, b"a", b"hover"), (1.0, 1, b"b", b"hover")],
                                           dtype=f["phases/data"].dtype)
        if stream == "setpoints":
            f["setpoints/data"].resize((1,))
            f["setpoints/data"][0] = (0.0, 0.0, 0.0, 0.0, 0, 0, 0)
        data = _retyped(f[f"{stream}/data"][()], field, dtype, value)
        del f[f"{stream}/data"]
        f[stream].create_dataset("data", data=data)
    s = open_session(session)
    other = "events" if stream == "gyro" else "gyro"
    assert stream not in s.streams and len(s[other].data) > 0
    assert s.problems == [f"stream {stream!r}: not read: field {field!r} has type "
                          f"{np.dtype(dtype)}, where a session stream holds {holds}"]
    result = CliRunner().invoke(main, ["info", str(session), "--width", "300"])
    assert result.exit_code == 0, result.output
    assert f"field {field!r} has type" in result.output


def test_root_attributes_of_the_wrong_type_are_dropped_and_listed(session):
    """An array where the uri is text crashed `info` (truth value of an array) and
    `info --json` (ndarray not JSON serializable); unknown keys' arrays read as lists."""
    with h5py.File(session, "a") as f:
        f.attrs["uri"] = np.arange(3)
        f.attrs["plan_name"] = np.array([b"a", b"b"])
        f.attrs["setpoint_rate_hz"] = "ten"
        f.attrs["someone_elses"] = np.zeros((2, 2))
    s = open_session(session)
    assert "uri" not in s.meta and "plan_name" not in s.meta and "setpoint_rate_hz" not in s.meta
    assert s.meta["someone_elses"] == [[0.0, 0.0], [0.0, 0.0]]
    for key in ("uri", "plan_name", "setpoint_rate_hz"):
        assert f"attribute {key!r} has the wrong type; ignored" in s.problems
    for args in (["info"], ["info", "--json"]):
        result = CliRunner().invoke(main, [*args, str(session)])
        assert result.exit_code == 0, result.output
    assert json.loads(result.output)["uri"] == ""


def test_a_period_too_short_to_be_a_log_rate_is_ignored(session):
    """period_s = 1e-300 made `info` expect a 300-digit number of rows."""
    with h5py.File(session, "a") as f:
        f["gyro"].attrs["period_s"] = 1e-300
    s = open_session(session)
    assert s["gyro"].period_s is None and "stream 'gyro': period_s 1e-300 ignored" in s.problems
    result = CliRunner().invoke(main, ["info", "--json", str(session)])
    assert result.exit_code == 0 and "expected" not in json.loads(result.output)["streams"]["gyro"]
