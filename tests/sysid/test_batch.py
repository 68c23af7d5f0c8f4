"""`sysid batch`: one model per group, a summary row per group, failures and Ctrl-C kept."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from click.testing import CliRunner

import sysid
import sysid.batch
from sysid.cli import main
from tests.sysid.flights import known_system, write_flight
from tests.sysid.systems import pole_error

FAST = ["--order", "4", "--past", "20", "--future", "10"]
A, B = "radio://0/80/2M/E7E7E7E7E7", "radio://0/80/2M/E7E7E7E7E8"


@pytest.fixture(scope="module")
def sessions(tmp_path_factory):
    """Two flights of vehicle A, one of B, one too short (vehicle C), one corrupt file."""
    d = tmp_path_factory.mktemp("batch")
    system = known_system()
    paths = [write_flight(d / f"a{i}.h5", system=system, seed=30 + i, n=1500,
                          metadata={"uri": A, "plan_name": "roll prbs"}).path for i in range(2)]
    paths.append(write_flight(d / "b0.h5", system=system, seed=40, n=1500,
                              metadata={"uri": B, "plan_name": "roll prbs"}).path)
    paths.append(write_flight(d / "c0.h5", system=system, seed=41, n=60,
                              phases=[(0.0, "excitation", "excitation")],
                              metadata={"uri": "radio://0/80/2M/C"}).path)
    junk = d / "junk.h5"
    junk.write_bytes(b"not a session" * 100)
    paths.append(junk)
    return paths, system


def run(*args: object) -> object:
    return CliRunner().invoke(main, [str(a) for a in args])


def test_batch_by_vehicle_writes_models_and_a_summary_with_failed_rows(sessions, tmp_path):
    paths, system = sessions
    out = tmp_path / "models"
    res = run("batch", *paths, "--out", out, "--group-by", "vehicle", *FAST)
    assert res.exit_code == 1, res.output  # two of four groups failed; two models written
    table = {r["group"]: r for r in json.loads((out / "summary.json").read_text())}
    a, b = table["radio-0-80-2M-E7E7E7E7E7"], table["radio-0-80-2M-E7E7E7E7E8"]
    assert a["flights"] == 2 and len(a["sessions"]) == 2 and b["flights"] == 1
    for row in (a, b):
        assert row["error"] is None and row["order"] == 4 and row["past"] == 20
        poles = np.array([re + 1j * im for re, im in row["poles"]])
        assert pole_error(system.poles(), poles) < 0.05
        assert min(row["validation_fit_percent"]) > 30
        model = sysid.load_model(row["model"])
        np.testing.assert_allclose(np.sort_complex(model.poles()), poles)
    assert table["radio-0-80-2M-C"]["error"] and table["radio-0-80-2M-C"]["model"] is None
    assert table["junk"]["error"] and table["junk"]["sessions"] == [str(paths[-1])]
    with (out / "summary.csv").open() as fh:
        rows = {r["group"]: r for r in csv.DictReader(fh)}
    assert set(rows) == set(table)
    assert rows["radio-0-80-2M-E7E7E7E7E7"]["order"] == "4"
    assert rows["junk"]["error"] == table["junk"]["error"]
    # the method (no --method: IEM, or PARSIM-K where it wins at the horizons) in every place
    assert a["method"] in ("iem", "parsim-k") and rows["radio-0-80-2M-E7E7E7E7E7"]["method"] == (
        a["method"]) and sysid.load_model(a["model"]).provenance["method"] == a["method"]
    header = " ".join(res.stdout.split())
    assert "order method focus score [%]" in header
    # not a terminal: plain progress lines, the last one at 100 %
    assert "batch: 3/3 (100 %)" in res.stderr
    # a second run into the same folder needs --force
    again = run("batch", *paths[:1], "--out", out, *FAST)
    assert again.exit_code == 2 and "--force" in again.stderr


def test_batch_group_names_and_no_knobs_selection(sessions, tmp_path):
    paths, _ = sessions
    groups, bad = sysid.batch.group_sessions(
        paths[:3], by="plan", read_meta=lambda p: {"plan_name": "roll prbs"})
    assert list(groups) == ["roll-prbs"] and not bad
    groups, _ = sysid.batch.group_sessions([paths[0], paths[0].with_name("x") / "a0.h5"],
                                           by="session", read_meta=dict)
    assert list(groups) == ["a0", "a0-2"]
    out = tmp_path / "auto"
    res = run("batch", paths[2], "--out", out, "--json")  # horizons and order chosen
    assert res.exit_code == 0, res.output
    [row] = json.loads(res.stdout)["groups"]
    assert row["error"] is None and 2 <= row["order"] <= 12 and row["stable"]
    # the same choice as `sysid identify` with no knobs: horizons, order and focus
    ident = run("identify", paths[2], "--json")
    assert ident.exit_code == 0, ident.output
    chosen = json.loads(ident.stdout)
    assert [row[k] for k in ("past", "future", "order", "focus")] == [
        chosen[k] for k in ("past", "future", "order", "focus")]
    # and what identify warns of, and the fits named by their outputs (batch gave neither)
    assert row["warnings"] == chosen["selection"]["warnings"]
    assert row["outputs"] == ["acc.z", "gyro.x", "gyro.y", "gyro.z"]  # the default outputs
    assert len(row["validation_fit_percent"]) == len(row["outputs"])
    with (out / "summary.csv").open() as fh:
        line = next(csv.DictReader(fh))
    assert line["focus"] == row["focus"] and line["outputs"].split(";") == row["outputs"]
    assert line["warnings"] == " | ".join(row["warnings"])


def test_ctrl_c_keeps_the_finished_groups(sessions, tmp_path, monkeypatch):
    paths, _ = sessions
    real, calls = sysid.batch.identify_group, []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(sysid.batch, "identify_group", interrupted)
    out = tmp_path / "stopped"
    res = run("batch", *paths[:3], "--out", out, *FAST)
    assert res.exit_code == 130 and "interrupted: 1 finished group" in res.stderr
    assert "; 2 group(s) not run: a1, b0 (the same command with --resume runs them)" in res.stderr
    [row] = json.loads((out / "summary.json").read_text())
    assert row["group"] == "a0" and row["error"] is None and (out / "a0.h5").exists()

    # the same command again is refused (it would replace a0), --resume runs a1 and b0 only
    again = run("batch", *paths[:3], "--out", out, *FAST)
    assert again.exit_code != 0 and "pass --resume to finish it" in again.stderr
    a0_model = (out / "a0.h5").read_bytes()
    monkeypatch.setattr(sysid.batch, "identify_group", real)
    counted = _count_groups(monkeypatch)
    res = run("batch", *paths[:3], "--out", out, *FAST, "--resume", "--json")
    assert res.exit_code == 0, res.output
    assert len(counted) == 2  # a0 kept as it was
    rows = json.loads((out / "summary.json").read_text())
    assert [r["group"] for r in rows] == ["a0", "a1", "b0"]
    assert rows[0] == row and (out / "a0.h5").read_bytes() == a0_model
    assert all(r["error"] is None and (out / f"{r['group']}.h5").exists() for r in rows)
    assert [g["group"] for g in json.loads(res.stdout)["groups"]] == ["a0", "a1", "b0"]


def test_resume_runs_deleted_and_failed_groups_and_refuses_another_batch(sessions, tmp_path,
                                                                         monkeypatch):
    paths, _ = sessions
    out = tmp_path / "m"
    assert run("batch", *paths[:2], "--out", out, *FAST).exit_code == 0
    other = run("batch", *paths[:2], "--out", out, "--order", "3", "--past", "20", "--future",
                "10", "--resume")
    assert other.exit_code != 0 and "\n" not in other.stderr.strip()
    assert "--resume: the batch in" in other.stderr and "--order 4 then, 3 now" in other.stderr
    both = run("batch", *paths[:2], "--out", out, *FAST, "--resume", "--force")
    assert both.exit_code != 0 and "give one of them" in both.stderr
    none = run("batch", *paths[:2], "--out", tmp_path / "new", *FAST, "--resume")
    assert none.exit_code != 0 and "holds no batch to resume" in none.stderr
    fewer = run("batch", paths[0], "--out", out, *FAST, "--resume")
    assert fewer.exit_code != 0 and "also has group(s) a1, which this command does not" in \
        fewer.stderr

    # a deleted model is made again, the others kept
    (out / "a1.h5").unlink()
    before = json.loads((out / "summary.json").read_text())
    counted = _count_groups(monkeypatch)
    res = run("batch", *paths[:2], "--out", out, *FAST, "--resume")
    assert res.exit_code == 0, res.output
    after = json.loads((out / "summary.json").read_text())
    assert len(counted) == 1 and after[0] == before[0] and (out / "a1.h5").exists()

    # a model file that is not the row's (another group's copied over it) is refused
    (out / "a0.h5").write_bytes((out / "a1.h5").read_bytes())
    swapped = run("batch", *paths[:2], "--out", out, *FAST, "--resume")
    assert swapped.exit_code != 0 and "changed since the batch" in swapped.stderr
    assert "a0 (a0.h5)" in swapped.stderr


def test_resume_refuses_groups_whose_sessions_changed(sessions, tmp_path, monkeypatch):
    paths, _ = sessions
    out = tmp_path / "by-vehicle"
    assert run("batch", paths[0], paths[2], "--out", out, "--group-by", "vehicle",
               *FAST).exit_code == 0
    res = run("batch", *paths[:3], "--out", out, "--group-by", "vehicle", *FAST, "--resume")
    assert res.exit_code != 0 and "changed since the batch" in res.stderr
    assert "radio-0-80-2M-E7E7E7E7E7 (its sessions)" in res.stderr
    # the same relative names in another folder are other files
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    for p in paths[:2]:
        (elsewhere / p.name).write_bytes(p.read_bytes())
    monkeypatch.chdir(paths[0].parent)
    rel = tmp_path / "rel"
    assert run("batch", paths[0].name, paths[1].name, "--out", rel, *FAST).exit_code == 0
    monkeypatch.chdir(elsewhere)
    moved = run("batch", paths[0].name, paths[1].name, "--out", rel, *FAST, "--resume")
    assert moved.exit_code != 0 and "a0 (its sessions)" in moved.stderr


def test_resume_runs_a_group_that_failed_again(sessions, tmp_path, monkeypatch):
    paths, _ = sessions
    out = tmp_path / "m"
    real = sysid.StateSpaceModel.save

    def full(self, path, *a, **k):
        if path.name == "a1.h5":
            raise OSError(28, "No space left on device")
        return real(self, path, *a, **k)

    monkeypatch.setattr(sysid.StateSpaceModel, "save", full)
    res = run("batch", *paths[:2], "--out", out, *FAST)
    assert res.exit_code == 1 and "No space left" in (out / "summary.csv").read_text()
    monkeypatch.setattr(sysid.StateSpaceModel, "save", real)
    counted = _count_groups(monkeypatch)
    res = run("batch", *paths[:2], "--out", out, *FAST, "--resume")
    assert res.exit_code == 0, res.output
    assert len(counted) == 1 and (out / "a1.h5").exists()
    assert [r["error"] for r in json.loads((out / "summary.json").read_text())] == [None, None]


def _count_groups(monkeypatch) -> list[int]:
    """Count the groups identified from here on."""
    real, counted = sysid.batch.identify_group, []
    monkeypatch.setattr(sysid.batch, "identify_group",
                        lambda *a, **k: counted.append(1) or real(*a, **k))
    return counted


def test_an_unexpected_failure_is_a_row_and_the_batch_goes_on(sessions, tmp_path, monkeypatch,
                                                              caplog):
    """Not only user errors: a bug in one group (here a KeyError, as a loader meeting an odd
    channel raised) or a lost cluster worker is that group's failed row, with its traceback
    in the log; the other groups are identified."""
    paths, _ = sessions
    real, calls = sysid.batch.identify_group, []

    def buggy(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            raise KeyError("gyro.q")
        return real(*args, **kwargs)

    monkeypatch.setattr(sysid.batch, "identify_group", buggy)
    out = tmp_path / "buggy"
    with caplog.at_level("ERROR", logger="sysid.batch"):
        res = run("batch", *paths[:3], "--out", out, *FAST)
    rows = {r["group"]: r for r in json.loads((out / "summary.json").read_text())}
    assert set(rows) == {"a0", "a1", "b0"}, res.output
    # some groups failed: exit 1 (a script sees it), one line naming how many and the first
    assert res.exit_code == 1 and res.stderr.strip().splitlines()[-1] == (
        f"error: 1 of the 3 group(s) failed; first: a0: {rows['a0']['error']}")
    assert "gyro.q" in rows["a0"]["error"] and "\n" not in rows["a0"]["error"]
    assert rows["a1"]["error"] is None and (out / "a1.h5").exists()
    assert rows["b0"]["error"] is None and (out / "b0.h5").exists()
    assert any(r.exc_info for r in caplog.records)


def test_a_group_of_open_loop_data_gets_a_direct_term_as_identify_does():
    """`sysid batch` passes choose_feedthrough="open-loop" as `sysid identify` does: a plant
    with a direct term, logged in open loop, keeps one."""
    from sysid.methods import get_method
    from tests.sysid.systems import random_stable_system

    system = random_stable_system(n_states=2, n_inputs=1, n_outputs=1, feedthrough=True,
                                  rng=np.random.default_rng(8))
    rng = np.random.default_rng(9)
    u = rng.standard_normal((1500, 1))
    y = system.simulate(u)
    data = sysid.IOData(u=u, y=y + 0.05 * y.std() * rng.standard_normal(y.shape), dt=0.02)
    iem = get_method("iem")
    out = sysid.batch.identify_group([[data]], method=iem, options=iem.options(), grid={},
                                     choose_focus=True, choose_feedthrough="open-loop")
    assert out["model"].provenance["feedthrough"] is True
    np.testing.assert_allclose(out["model"].D, system.D, atol=0.05)


def test_models_never_replace_the_sessions_they_come_from(tmp_path):
    """``--group-by session`` names a group after its file: ``--out`` the sessions' own folder
    replaced every recorded flight with its model, exit 0 (CLI fuzz). Now one line, nothing
    written; an existing model file needs --force; --out on a device is one line too."""
    import hashlib

    flight = write_flight(tmp_path / "flight.h5", system=known_system(), seed=50, n=1500).path
    before = hashlib.sha256(flight.read_bytes()).hexdigest()
    res = run("batch", flight, "--out", tmp_path, *FAST)
    assert res.exit_code == 2 and res.output.strip().splitlines() == [
        f"error: --out {tmp_path}: the model of group 'flight' (flight.h5) would replace the "
        f"session {flight}, an input of this batch; choose another folder for the models"]
    assert hashlib.sha256(flight.read_bytes()).hexdigest() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.h5"]
    with pytest.raises(sysid.ParameterError, match="an input of this batch"):  # the library too
        sysid.batch.run_batch({"flight": [flight]}, out_dir=tmp_path, load=lambda p: [],
                              method=sysid.methods.get_method("iem"),
                              options=sysid.methods.get_method("iem").options(), grid={})
    out = tmp_path / "models"
    assert run("batch", flight, "--out", out, *FAST).exit_code == 0
    (out / "summary.json").unlink()  # a model file left without its summary
    res = run("batch", flight, "--out", out, *FAST)
    assert res.exit_code == 2 and "flight.h5 exists; pass --force" in res.output
    assert run("batch", flight, "--out", out, *FAST, "--force").exit_code == 0
    res = run("batch", flight, "--out", "/dev/null", *FAST)
    assert res.exit_code == 2 and "exists and is not a folder" in res.output


def test_flights_counts_sessions_not_the_experiments_in_them(tmp_path):
    """A flight with a PRBS and a chirp is two experiments of one flight (window auto)."""
    phases = [(0.0, "takeoff", "takeoff"), (5.0, "prbs", "excitation"), (25.0, "rest", "hover"),
              (27.0, "chirp", "excitation"), (37.0, "land", "landing")]
    path = write_flight(tmp_path / "two.h5", system=known_system(), seed=8, phases=phases).path
    res = run("batch", path, "--out", tmp_path / "m", *FAST, "--json")
    assert res.exit_code == 0, res.output
    [row] = json.loads((tmp_path / "m" / "summary.json").read_text())
    assert row["flights"] == 1 and row["error"] in (None, "")


@pytest.mark.parametrize("damage", [
    lambda rows: json.dumps([{**rows[0], "flights": "many"}]),
    lambda rows: json.dumps([{**rows[0], "stable": "false"}]),
    lambda rows: json.dumps([{**rows[0], "score_percent": float("nan")}]),
    lambda rows: json.dumps([{**rows[0], "poles": [[1.0]]}]),
    lambda rows: json.dumps([5]),
    lambda rows: json.dumps({"rows": rows}),
    lambda rows: "[" * 100_000,  # nested past the parser's recursion limit
])
def test_resume_reads_a_damaged_summary_as_one_line(sessions, tmp_path, damage):
    paths, _ = sessions
    out = tmp_path / "m"
    assert run("batch", paths[0], "--out", out, *FAST).exit_code == 0
    summary = out / "summary.json"
    summary.write_text(damage(json.loads(summary.read_text())))
    res = run("batch", paths[0], "--out", out, *FAST, "--resume")
    assert res.exit_code == 2 and isinstance(res.exception, SystemExit)
    [line] = res.stderr.strip().splitlines()
    assert "batch.json or summary.json cannot be read" in line and "--force" in line


def test_progress_follows_each_groups_models(sessions, tmp_path, monkeypatch):
    """Not on a terminal, a long group says which it is and how far its selection got (here
    every time: the heartbeat set to 0 s)."""
    import sysid.cli_progress

    paths, _ = sessions
    monkeypatch.setattr(sysid.cli_progress, "HEARTBEAT_S", 0.0)
    res = run("batch", *paths[:2], "--out", tmp_path / "m", "--order", "4")
    assert res.exit_code == 0, res.output
    lines = [ln for ln in res.stderr.splitlines() if " models" in ln]
    assert any(ln.startswith("batch: 0/2 (0 %)") and ", a0: " in ln for ln in lines)
    assert any(ln.startswith("batch: 1/2 (50 %)") and ", a1: " in ln for ln in lines)
    last = [ln for ln in lines if ", a0: " in ln][-1].rsplit(", a0: ", 1)[1]
    done, total = map(int, last.removesuffix(" models").split("/"))
    assert 0 < done <= total
