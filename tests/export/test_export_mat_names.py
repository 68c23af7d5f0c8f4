"""``groundstation export --to mat``: every stream and field under its own MATLAB name, whatever
the session's names (long, non-ASCII, two made alike), never a traceback."""

from __future__ import annotations

import numpy as np
import scipy.io
from click.testing import CliRunner

from cfsession.schema import Field, StreamSpec
from cfsession.writer import SessionWriter
from groundstation.cli import main


def _export(session, out):
    res = CliRunner().invoke(main, ["export", str(session), "--to", "mat", "--out", str(out)])
    assert res.exit_code == 0, res.output
    return scipy.io.loadmat(out, simplify_cells=True)


def test_imported_64_character_names_export(tmp_path):
    """Two variables sharing a 59-character short name are fields of 64 characters, which
    savemat refused with a ValueError traceback (MATLAB names have at most 63)."""
    header = [f"g{i}." + "v" * 61 for i in (1, 2)]
    csv = tmp_path / "Blk-20240101T10-00-00.csv"
    csv.write_text("Timestamp," + ",".join(header) + "\n10,1,2\n20,3,4\n")
    res = CliRunner().invoke(main, ["import", str(csv), "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    m = _export(tmp_path / "o" / f"{tmp_path.name}.h5", tmp_path / "f.mat")
    fields = m["streams"]["Blk"]
    long = [f for f in fields if f.startswith("g")]
    assert len(long) == 2 and all(len(f) <= 63 for f in long)
    np.testing.assert_array_equal([fields[f] for f in long], [[1, 3], [2, 4]])
    assert set(m["units"]["Blk"]) == set(fields)


def test_names_made_alike_or_non_ascii_are_each_kept(tmp_path):
    """``acc+motor`` and ``acc_motor`` (or fields ``a.b`` and ``a_b``) were both written as
    ``acc_motor``: one stream silently lost; a non-ASCII name was a UnicodeEncodeError."""

    def spec(name, fields):
        return StreamSpec(name=name, kind="log", period_s=0.01, description="",
                          fields=(Field("host_time", "<f8", "s", ""),
                                  *(Field(f, "<f8", f"u{i}", f) for i, f in enumerate(fields))))

    specs = [spec("acc+motor", ["a.b", "a_b"]), spec("acc_motor", ["x"]), spec("blä", ["é"])]
    path = tmp_path / "s.h5"
    with SessionWriter(path, streams=specs, metadata={"uri": "x"}) as w:
        for k, s in enumerate(specs):
            w.extend(s.name, [(0.01 * j, *(10.0 * k + j + i for i in range(len(s.fields) - 1)))
                              for j in range(3)])
    m = _export(path, tmp_path / "s.mat")
    st, units = m["streams"], m["units"]
    assert set(st) == {"acc_motor", "acc_motor_2", "bl_"}
    np.testing.assert_array_equal(st["acc_motor"]["x"], [10, 11, 12])  # its own name kept
    both = st["acc_motor_2"]
    assert set(both) == {"host_time", "a_b", "a_b_2"}
    np.testing.assert_array_equal(both["a_b"], [1, 2, 3])  # the field named a_b
    np.testing.assert_array_equal(both["a_b_2"], [0, 1, 2])
    assert (units["acc_motor_2"]["a_b"], units["acc_motor_2"]["a_b_2"]) == ("u1", "u0")
    np.testing.assert_array_equal(st["bl_"]["f__"], [20, 21, 22])
    assert units["bl_"]["f__"] == "u0"
    # and the way back: each MATLAB name to the session's (csv and parquet: stream_files)
    names = m["names"]
    assert {k: v["stream"] for k, v in names.items()} == {
        "acc_motor": "acc_motor", "acc_motor_2": "acc+motor", "bl_": "blä"}
    assert names["acc_motor_2"]["fields"] == {"host_time": "host_time", "a_b": "a_b",
                                              "a_b_2": "a.b"}
    assert names["bl_"]["fields"]["f__"] == "é"
