"""The scheduler killed mid-run (one line, the finished groups kept), and a task whose
workers all die (Dask's ``KilledWorker``): a failed row of a batch, one line on the CLI."""

from __future__ import annotations

import json
import logging
import re
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from sysid.cluster import (
    SchedulerLost,
    run_pasts,
    watching,
)
from sysid.errors import ClusterError
from tests.sysid import cluster_fakes
from tests.sysid.cluster_faults.support import (
    DEADLINE_S,
    ROOT,
    clean,
    env,
    run_sysid,
    summary,
)
from tests.sysid.flights import known_system, write_flight

distributed = pytest.importorskip("distributed")


def test_scheduler_killed_mid_batch_is_one_line_keeping_finished_groups(
        killable: tuple[subprocess.Popen[str], str], tmp_path: Path) -> None:
    server, address = killable
    system = known_system()
    paths = [write_flight(tmp_path / f"{n}.h5", system=system, seed=i, n=1200).path
             for i, n in enumerate(["a_0", "b_block", "c_block"])]
    out = tmp_path / "out"
    cmd = [sys.executable, "-c", "from sysid.cli import main; main()", "batch", *map(str, paths),
           "--out", str(out), "--order", "4", "--past", "5", "--future", "5",
           "--scheduler", address]
    t0 = time.monotonic()
    batch = subprocess.Popen(cmd, cwd=ROOT, env=env(), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        while time.monotonic() - t0 < DEADLINE_S and batch.poll() is None:
            if (out / "summary.json").exists() and summary(out):
                break
            time.sleep(0.05)
        server.kill()  # the scheduler (and its worker) die mid-batch
        _, stderr = batch.communicate(timeout=DEADLINE_S)
    finally:
        batch.kill()
    assert time.monotonic() - t0 < DEADLINE_S
    lines = clean(stderr)
    assert lines[-1] == (
        f"error: --scheduler {address}: lost the connection to the scheduler; 1 finished "
        f"group(s) kept in {out / 'summary.json'} and {out / 'summary.csv'}; 2 group(s) not "
        "run: b_block, c_block (the same command with --resume runs them)"), stderr
    assert batch.returncode == 2
    assert not any("100 %" in line or "done" in line for line in lines)
    assert summary(out) == ["a_0"]
    # here, without the cluster: the scheduler is no setting of the models
    resumed = subprocess.run([*cmd[:cmd.index("--scheduler")], "--resume"], cwd=ROOT, env=env(),
                             capture_output=True, text=True, timeout=DEADLINE_S)
    assert resumed.returncode == 0, resumed.stderr
    assert summary(out) == ["a_0", "b_block", "c_block"]


def test_scheduler_killed_mid_sweep_is_scheduler_lost(
        killable: tuple[subprocess.Popen[str], str]) -> None:
    """The sweep's tasks (:func:`run_pasts`): the scheduler goes while they block."""
    server, address = killable
    client = distributed.Client(address, timeout=5)
    done: list[int] = []

    def finished(past: int, _rows: Any) -> None:
        done.append(past)
        server.kill()

    t0 = time.monotonic()
    try:
        with watching(label="cluster", poll_s=0.1), \
                pytest.raises(SchedulerLost, match=r"^cluster: lost the connection to the "
                                                   r"scheduler$"):
            run_pasts(client, task=cluster_fakes.fake_past, shared={}, common={"first": 1},
                      pasts=[1, 2, 3], finished=finished)
    finally:
        client.close(timeout=10)
    assert done == [1] and time.monotonic() - t0 < DEADLINE_S


# ----------------------------------------------------- workers killed while running a task
_LOST = (r"worker lost 4 times while running it \(the scheduler's allowed-failures is 3; the "
         r"last was tcp://127\.0\.0\.1:\d+, see its log\)")


def test_group_whose_workers_all_die_is_a_failed_row_without_traceback(
        fake_batch: Any, four: tuple[Any, Any], tmp_path: Path,
        caplog: pytest.LogCaptureFixture) -> None:
    """Group ``k`` kills every worker that runs it (once ``a`` is in): Dask gives up on it
    (``KilledWorker``). It is a failed row with that reason in one line, logged without a
    traceback; the batch goes on and keeps ``a``."""
    _, client = four

    def progress(done: int, _total: int) -> None:
        if done == 1:
            cluster_fakes.LOSE.set()

    t0 = time.monotonic()
    with caplog.at_level(logging.INFO, logger="sysid"), watching(label="cluster", poll_s=0.1):
        rows = fake_batch(["a_0", "k_die"], client, progress=progress)
    assert time.monotonic() - t0 < DEADLINE_S
    assert [(r.group, r.error is None) for r in rows] == [("a", True), ("k", False)]
    assert re.fullmatch(_LOST, rows[1].error), rows[1].error
    assert [r["error"] for r in json.loads((tmp_path / "out" / "summary.json").read_text())
            ] == [None, rows[1].error]
    sysid_records = [r for r in caplog.records if r.name.startswith("sysid")]
    assert not any(r.exc_info for r in sysid_records), [r.getMessage() for r in sysid_records]
    assert f"group k: {rows[1].error}" in [r.getMessage() for r in sysid_records]


def test_cli_batch_group_whose_workers_all_die_is_one_line(tmp_path: Path) -> None:
    """The command, on a scheduler of its own process: no traceback on stderr; the group is a
    failed row and, as it is the only one, the batch ends with that reason (exit 2)."""
    proc = subprocess.Popen([sys.executable, "-m", "tests.sysid.cluster_fakes", "4"], cwd=ROOT,
                            env=env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        address = proc.stdout.readline().strip()
        assert address.startswith("tcp://127.0.0.1:"), address
        path = write_flight(tmp_path / "k_die.h5", system=known_system(), seed=3, n=1200).path
        out = tmp_path / "out"
        batch, took = run_sysid("batch", path, "--out", out, "--order", "4", "--past", "5",
                             "--future", "5", "--scheduler", address)
    finally:
        proc.kill()
        proc.wait(timeout=30)
    assert batch.returncode == 2, batch.stderr
    lines = clean(batch.stderr)
    assert re.fullmatch(f"error: every one of the 1 group\\(s\\) failed; first: k_die: {_LOST}",
                        lines[-1]), lines
    [row] = json.loads((out / "summary.json").read_text())
    assert row["group"] == "k_die" and re.fullmatch(_LOST, row["error"])
    assert took < DEADLINE_S


def test_sweep_past_whose_workers_all_die_is_one_line(four: tuple[Any, Any]) -> None:
    """A sweep needs every past: it ends with a :class:`ClusterError` naming the past."""
    _, client = four
    cluster_fakes.LOSE.set()
    t0 = time.monotonic()
    with watching(label="cluster", poll_s=0.1), \
            pytest.raises(ClusterError, match=f"^cluster: past 2: {_LOST}$") as err:
        run_pasts(client, task=cluster_fakes.fake_past, shared={}, common={"first": 1, "die": 2},
                  pasts=[2], finished=lambda *_: None)
    assert not isinstance(err.value, SchedulerLost)
    assert time.monotonic() - t0 < DEADLINE_S
