"""A file that is no TOML flight plan (a session or model .h5, a .mat, any binary) given as the
plan: one line saying so, not the UTF-8 decoder's complaint about byte 0x89."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.errors import PlanError
from groundstation.plan import load_plan


def _model_like(path):
    with h5py.File(path, "w") as f:
        f["A"] = np.eye(2)
    return path


@pytest.mark.parametrize("command", [["plan", "check", "{plan}"],
                                     ["fly", "{plan}", "--uri", "sim://0?speed=inf", "--out",
                                      "{out}"]])
def test_an_hdf5_file_is_not_a_flight_plan(tmp_path, command):
    model = _model_like(tmp_path / "model.h5")
    args = [a.format(plan=model, out=tmp_path / "s") for a in command]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2, res.output
    [line] = res.output.strip().splitlines()
    assert line.startswith(f"error: {model}: not a TOML flight plan (it looks like an HDF5 file")
    assert "codec" not in line and "0x89" not in line and "e.g. prbs-3axis" in line
    assert not (tmp_path / "s").exists()


def test_other_binary_is_not_utf8_text(tmp_path):
    blob = tmp_path / "plan.toml"
    blob.write_bytes(bytes(range(128, 256)))
    with pytest.raises(PlanError, match=r"plan\.toml: not a TOML flight plan \(not UTF-8 text\)"):
        load_plan(blob)


def test_a_csv_or_json_file_is_not_a_flight_plan(tmp_path):
    """A CSV log or a model's JSON given as the plan got "x.csv:1: invalid TOML: ...; fix the
    syntax on that line", as if it were a plan with a typo; a .toml file keeps that line."""
    for name, suffix, text in (("log.csv", "csv", "t,gyro.x\n0,1\n"),
                               ("model.json", "json", '{"A": [[1]]}\n')):
        path = tmp_path / name
        path.write_text(text)
        with pytest.raises(PlanError, match=rf"{name}: not a TOML flight plan \(a \.{suffix} "
                                            r"file that does not read as TOML: .*\); give a plan "
                                            r"file \(\.toml\)") as err:
            load_plan(path)
        assert "fix the syntax" not in str(err.value)
    typo = tmp_path / "typo.toml"
    typo.write_text("name = \n")
    with pytest.raises(PlanError, match=r"typo\.toml:1: invalid TOML: .*fix the syntax"):
        load_plan(typo)


def test_a_byte_order_mark_is_skipped_as_toml_tools_do(tmp_path):
    """A plan saved by Notepad starts with a UTF-8 BOM: "invalid TOML: Invalid statement (line 1,
    column 1)", not naming it (review D). It reads as the plan without it, in a file (also with
    another suffix) and as a session's plan text; the plan's text keeps no BOM."""
    from groundstation.plan import SHIPPED_PLANS_DIR, parse_plan

    text = (SHIPPED_PLANS_DIR / "hover-check.toml").read_text()
    for name in ("notepad.toml", "notepad.txt"):
        path = tmp_path / name
        path.write_bytes(b"\xef\xbb\xbf" + text.encode())
        plan = load_plan(path)
        assert plan.name == "hover-check" and plan.text == text
    assert parse_plan(text="\ufeff" + text).text == text
    res = CliRunner().invoke(main, ["plan", "check", str(tmp_path / "notepad.toml")])
    assert res.exit_code == 0, res.output


def test_a_text_plan_still_loads(tmp_path):
    assert load_plan("hover-check").name == "hover-check"


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="POSIX FIFO")
def test_a_fifo_or_a_device_is_no_plan_and_never_waits(tmp_path):
    """Opening a FIFO as the plan waited for a writer (until Ctrl-C); ``/dev/zero`` read until
    the kernel refused 64 GB (CLI fuzz)."""
    import os

    fifo = tmp_path / "plan.toml"
    os.mkfifo(fifo)
    for path in (fifo, "/dev/zero"):
        with pytest.raises(PlanError, match=r": not a regular file \(a device, FIFO or socket\)"):
            load_plan(path)
    res = CliRunner().invoke(main, ["fly", str(fifo), "--uri", "sim://0?speed=inf", "--out",
                                    str(tmp_path / "s")])
    assert res.exit_code == 2 and "not a regular file" in res.output


def test_a_file_of_megabytes_is_no_plan(tmp_path):
    big = tmp_path / "big.toml"
    big.write_text("# " + "x" * (2 * 1024 * 1024) + "\n")
    with pytest.raises(PlanError, match=r"big\.toml: larger than 1024 KiB, so not a flight plan"):
        load_plan(big)
