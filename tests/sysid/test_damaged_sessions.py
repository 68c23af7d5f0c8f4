"""A damaged or crash-truncated session is never used in silence: every ``sysid`` command that
reads sessions (and ``--validate``) repeats the problems ``groundstation info`` lists as
warnings naming the file, from the one place sessions are read (``sysid/session_io.py``), and
``sysid identify`` says how many samples it identified from."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import h5py
import pytest
from click.testing import CliRunner

from cfsession import open_session
from sysid.cli import main
from sysid.session_io import load_experiments
from tests.sysid.flights import known_system, write_flight

FAST = ["--order", "4", "--past", "20", "--future", "10"]
LOGGER = "sysid.session_io"


def damage_chunk(path: Path, *, stream: str = "gyro", chunk: int = 20) -> None:
    """Overwrite one compressed chunk of ``stream`` so it no longer inflates."""
    with h5py.File(path, "r") as f:
        info = f[f"{stream}/data"].id.get_chunk_info(chunk)
    raw = bytearray(path.read_bytes())
    raw[info.byte_offset: info.byte_offset + info.size] = b"\xff" * info.size
    path.write_bytes(bytes(raw))


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("damaged")
    system = known_system()
    good = write_flight(d / "good.h5", system=system, seed=21).path
    bad = d / "bad.h5"
    shutil.copy(good, bad)
    damage_chunk(bad)
    killed = d / "killed.h5"
    shutil.copy(good, killed)
    with h5py.File(killed, "r+") as f:  # as a writer that died leaves it
        f.attrs["closed_cleanly"] = 0
    model = d / "model.h5"
    res = CliRunner().invoke(main, ["identify", str(good), *FAST, "--out", str(model)])
    assert res.exit_code == 0, res.output
    return {"good": good, "bad": bad, "killed": killed, "model": model, "dir": d}


def _problems(path: Path) -> list[str]:
    problems = open_session(path).problems
    assert problems, path  # the fixture made them damaged
    return problems


def _warned(caplog, path: Path) -> list[str]:
    return [r.getMessage() for r in caplog.records
            if r.levelno == logging.WARNING and r.getMessage().startswith(f"{path}: problem: ")]


def test_the_fixture_files_have_the_problems_info_lists(files) -> None:
    assert any("'gyro': unreadable from row" in p for p in _problems(files["bad"]))
    assert any("did not close" in p for p in _problems(files["killed"]))
    assert open_session(files["good"]).problems == []


def test_load_experiments_warns_each_problem_once_naming_the_file(files, caplog) -> None:
    for key in ("bad", "killed"):
        caplog.clear()
        with caplog.at_level(logging.WARNING, logger=LOGGER):
            load_experiments(files[key])
        assert _warned(caplog, files[key]) == [f"{files[key]}: problem: {p}"
                                               for p in _problems(files[key])]
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        load_experiments(files["good"])
    assert not [r for r in caplog.records if "problem" in r.getMessage()]


def _commands(files: dict[str, Path], key: str, tmp: Path) -> dict[str, list[str]]:
    s, m, good = str(files[key]), str(files["model"]), str(files["good"])
    return {
        "identify": ["identify", s, *FAST],
        "identify --validate": ["identify", good, *FAST, "--validate", s],
        "compare": ["compare", m, s],
        "resid": ["resid", m, s],
        "order": ["order", s, "--past", "20", "--future", "10"],
        "sweep": ["sweep", s, "--pasts", "20", "--futures", "10", "--orders", "4"],
        "batch": ["batch", s, "--out", str(tmp / "batch"), *FAST],
    }


@pytest.mark.parametrize("command", ["identify", "identify --validate", "compare", "resid",
                                     "order", "sweep", "batch"])
@pytest.mark.parametrize("key", ["bad", "killed"])
def test_every_command_repeats_the_problems_as_warnings(files, key, command, caplog,
                                                         tmp_path) -> None:
    argv = _commands(files, key, tmp_path)[command]
    with caplog.at_level(logging.WARNING, logger=LOGGER):
        res = CliRunner().invoke(main, argv)
    assert res.exit_code == 0, res.output
    problems = _problems(files[key])
    assert _warned(caplog, files[key]) == [f"{files[key]}: problem: {p}" for p in problems]


def test_identify_says_how_many_samples_it_identified_from(files) -> None:
    counts = {}
    for key in ("good", "bad"):
        js = CliRunner().invoke(main, ["identify", str(files[key]), *FAST, "--json"])
        assert js.exit_code == 0, js.output
        (counts[key],) = json.loads(js.stdout)["n_samples"]
        text = CliRunner().invoke(main, ["identify", str(files[key]), *FAST])
        assert text.exit_code == 0, text.output
        assert (f"identified from {counts[key]} samples ({counts[key] * 0.02:.1f} s at dt "
                f"0.02 s) of {files[key]}") in text.stdout
    assert counts["bad"] < counts["good"]  # the damaged one is read as far as it goes
    both = CliRunner().invoke(main, ["identify", str(files["good"]), str(files["bad"]), *FAST])
    assert both.exit_code == 0, both.output
    total = counts["good"] + counts["bad"]
    assert (f"identified from {total} samples ({total * 0.02:.1f} s at dt 0.02 s) in 2 "
            f"experiments: {files['good']} {counts['good']}, {files['bad']} {counts['bad']}"
            ) in both.stdout
