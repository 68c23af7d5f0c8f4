"""A Dask cluster that cannot do the work ends ``--scheduler`` runs with one line, in bounded
time: an address that accepts but never answers, one that answers something else, a scheduler
without workers, workers lost mid-run, the scheduler lost mid-run, a scheduler that stops
answering (``SIGSTOP``) before the client has started or during a sweep's scatter. A task whose
workers all die (Dask's ``KilledWorker``) is a failed row of a batch, in one line. And a batch
on the cluster gives the local batch's rows: in input order, each group's own time.

Everything listens on 127.0.0.1 (ports the system chooses). The code's timeouts are shortened
(``SYSID_DASK_*`` environment variables, :func:`sysid.cluster.watching`) so the tests do not
depend on the machine's load; the deadlines asserted are generous."""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sysid.batch
import sysid.cluster
import sysid.cluster.connection
import sysid.cluster.runs
from sysid.batch import BatchRow, run_batch
from sysid.cluster import (
    CONNECT_ENV,
    RESEND_LIMIT,
    WORKER_WAIT_ENV,
    DataLost,
    SchedulerLost,
    connect,
    dashboard_link,
    run_pasts,
    scatter,
    task_result,
    watching,
)
from sysid.data import IOData
from sysid.errors import ClusterError, ParameterError
from sysid.methods import get_method
from tests.sysid import cluster_fakes
from tests.sysid.flights import known_system, write_flight

distributed = pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parents[2]
#: The connect timeout the commands get here, and the most any fault may take to be reported
#: (process start-up included, on a loaded machine).
CONNECT_S = 2.0
DEADLINE_S = 40.0


# ---------------------------------------------------------------------------------- helpers
class _Listener:
    """A TCP listener on 127.0.0.1 that accepts every connection and keeps it open, sending
    ``greeting`` (if any) and then nothing."""

    def __init__(self, greeting: bytes = b"") -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen()
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        self.greeting, self.conns = greeting, []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:  # closed
                return
            self.conns.append(conn)
            if self.greeting:
                conn.sendall(self.greeting)

    def close(self) -> None:
        self.sock.close()
        for c in self.conns:
            c.close()


@pytest.fixture
def silent() -> Iterator[_Listener]:
    listener = _Listener()
    yield listener
    listener.close()


@pytest.fixture
def garbage() -> Iterator[_Listener]:
    listener = _Listener(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n" * 4)
    yield listener
    listener.close()


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("faults")
    return write_flight(d / "s0.h5", system=known_system(), seed=50, n=1200).path


def _env() -> dict[str, str]:
    return {**os.environ, CONNECT_ENV: str(CONNECT_S), WORKER_WAIT_ENV: "2",
            "PYTHONPATH": str(ROOT)}


def _sysid(*args: object) -> tuple[subprocess.CompletedProcess[str], float]:
    """Run the ``sysid`` command; (its result, seconds it took)."""
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", "from sysid.cli import main; main()",
                           *map(str, args)], capture_output=True, text=True, timeout=DEADLINE_S,
                          env=_env(), cwd=ROOT)
    return proc, time.monotonic() - t0


def _clean(stderr: str) -> list[str]:
    """stderr's lines, checked to hold no traceback."""
    assert "Traceback" not in stderr and "Error:" not in stderr.replace("error:", ""), stderr
    return stderr.strip().splitlines()


def _cli(*args: object) -> tuple[Any, float]:
    """Run the ``sysid`` command in this process (so a test can patch what it calls); (its
    click result, seconds it took). A command still running after :data:`DEADLINE_S` fails
    the test (its thread is left to the fixtures' teardown)."""
    from click.testing import CliRunner

    from sysid.cli import main

    out: list[Any] = []
    t0 = time.monotonic()
    runner = threading.Thread(target=lambda: out.append(
        CliRunner().invoke(main, [str(a) for a in args])), daemon=True)
    runner.start()
    runner.join(DEADLINE_S)
    if not out:
        pytest.fail(f"sysid {' '.join(map(str, args))}: still running after {DEADLINE_S:g} s")
    return out[0], time.monotonic() - t0


def _sweep_args(session: Path, address: str) -> list[object]:
    return ["sweep", session, "--pasts", "20,30", "--futures", "10", "--orders", "4",
            "--scheduler", address]


# -------------------------------------------------------------------------------- connecting
def test_silent_address_is_one_line_within_the_connect_timeout(session: Path,
                                                                silent: _Listener) -> None:
    proc, took = _sysid(*_sweep_args(session, silent.address))
    assert proc.returncode == 2, proc.stderr
    assert _clean(proc.stderr) == [
        f"error: --scheduler {silent.address}: cannot connect (the connection is accepted but "
        f"nothing answers within {CONNECT_S:g} s: is it a Dask scheduler? the scheduler's "
        "port is usually 8786, the dashboard's 8787)"]
    assert took < DEADLINE_S
    assert silent.conns  # it did connect: the handshake is what never came


def test_non_dask_service_is_one_line(session: Path, garbage: _Listener) -> None:
    proc, took = _sysid(*_sweep_args(session, garbage.address))
    assert proc.returncode == 2, proc.stderr
    [line] = _clean(proc.stderr)
    assert line.startswith(f"error: --scheduler {garbage.address}: does not speak the Dask "
                           "protocol (")
    assert "EiB" not in line and took < DEADLINE_S


def test_connect_bounds_the_handshake_in_process(silent: _Listener, garbage: _Listener) -> None:
    """The library call too: no hang, no MemoryError, within its timeout."""
    for listener, words in ((silent, "nothing answers within 1 s"),
                            (garbage, "does not speak the Dask protocol")):
        t0 = time.monotonic()
        with pytest.raises(ClusterError, match=words):
            connect(listener.address, timeout_s=1.0)
        assert time.monotonic() - t0 < 20


def test_refused_port_is_one_line() -> None:
    free = socket.socket()
    free.bind(("127.0.0.1", 0))
    port = free.getsockname()[1]
    free.close()  # nothing listens there now
    t0 = time.monotonic()
    with pytest.raises(ClusterError) as err:
        connect(f"tcp://127.0.0.1:{port}", timeout_s=1.0)
    assert str(err.value) == (f"--scheduler tcp://127.0.0.1:{port}: cannot connect "
                              "(Connection refused; tried for 1 s)")
    assert time.monotonic() - t0 < 20


def test_timeouts_from_the_environment_are_checked(monkeypatch: pytest.MonkeyPatch) -> None:
    from sysid.cluster import connect_timeout_s, worker_wait_s

    monkeypatch.setenv(CONNECT_ENV, "3.5")
    monkeypatch.setenv(WORKER_WAIT_ENV, "0")
    assert connect_timeout_s() == 3.5
    with pytest.raises(ParameterError, match=f"^{WORKER_WAIT_ENV}='0': give a number"):
        worker_wait_s()


def test_scheduler_without_workers_is_one_line(session: Path) -> None:
    with distributed.LocalCluster(n_workers=0, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address="127.0.0.1:0") as cluster:
        address = cluster.scheduler_address
        proc, took = _sysid(*_sweep_args(session, address))
    assert proc.returncode == 2, proc.stderr
    lines = _clean(proc.stderr)
    assert lines[0].startswith(f"dask: {address}, 0 worker(s)")
    assert lines[0].endswith(f"; waiting up to {CONNECT_S:g} s for one")
    assert lines[1:] == [f"error: --scheduler {address}: the scheduler has no workers (waited "
                         f"{CONNECT_S:g} s); start one with `dask worker {address}`"]
    assert took < DEADLINE_S


# ------------------------------------------------------------------------------ during a run
@pytest.fixture
def fake_batch(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[Any]:
    """``run(names, client, **kw)``: a batch of groups named after their delays
    (:mod:`tests.sysid.cluster_fakes`) on ``client``; blocked tasks are released at the end."""
    monkeypatch.setattr(sysid.batch, "identify_group", cluster_fakes.fake_identify)
    rng = np.random.default_rng(1)

    def load(paths: list[Path]) -> list[list[Any]]:  # the fake reads only the name
        return [[IOData(u=rng.normal(size=(200, 1)), y=rng.normal(size=(200, 1)), dt=0.02,
                        source=str(paths[0]))]]

    def run(names: list[str], client: Any, **kw: Any) -> list[Any]:
        groups = {n.partition("_")[0]: [tmp_path / f"{n}.h5"] for n in names}
        return run_batch(groups, out_dir=tmp_path / "out", load=load,
                         method=get_method("iem"), options=get_method("iem").options(),
                         grid={}, client=client, **kw)

    cluster_fakes.GATE.clear()
    yield run
    cluster_fakes.GATE.set()


@pytest.fixture
def threads() -> Iterator[tuple[Any, Any]]:
    """A scheduler with one worker of two threads, in this process; a client of it."""
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                       protocol="tcp://", host="127.0.0.1",
                                       dashboard_address="127.0.0.1:0")
    client = distributed.Client(cluster.scheduler_address, timeout=10)
    yield cluster, client
    cluster_fakes.GATE.set()
    client.close(timeout=10)
    cluster.close(timeout=10)


def _summary(out: Path) -> list[str]:
    return [r["group"] for r in json.loads((out / "summary.json").read_text())]


def test_workers_lost_mid_batch_warn_then_end_keeping_finished_groups(
        fake_batch: Any, threads: tuple[Any, Any], tmp_path: Path) -> None:
    cluster, client = threads
    [worker] = cluster.workers.values()

    def progress(done: int, _total: int) -> None:
        if done == 1:  # the fast group is in: the worker goes, its tasks still blocked
            cluster.sync(worker.close, executor_wait=False, reason="test")

    warnings: list[str] = []
    t0 = time.monotonic()
    with watching(label="cluster", worker_wait_s=1.0, poll_s=0.1, notify=warnings.append), \
            pytest.raises(ClusterError) as err:
        fake_batch(["a_0", "b_block", "c_block", "d_block"], client, progress=progress)
    assert time.monotonic() - t0 < DEADLINE_S
    assert not isinstance(err.value, SchedulerLost)
    addr = cluster.scheduler_address
    assert str(err.value) == (
        f"cluster: the scheduler had no workers for 1 s; start one with `dask worker {addr}`; "
        f"1 finished group(s) kept in {tmp_path / 'out' / 'summary.json'} and "
        f"{tmp_path / 'out' / 'summary.csv'}; 3 group(s) not run: b, c, d")
    assert warnings == [f"cluster: the scheduler has no workers; waiting up to 1 s for one "
                        f"(start one with `dask worker {addr}`)"]
    assert _summary(tmp_path / "out") == ["a"]  # the not-run groups are no failed rows


def test_unreadable_sessions_are_not_counted_as_finished_groups(
        fake_batch: Any, threads: tuple[Any, Any], tmp_path: Path) -> None:
    """The rows given to the batch (sessions that could not be read) are in the summary but
    never ran: the count of finished groups in the fault's line leaves them out."""
    cluster, client = threads
    [worker] = cluster.workers.values()
    bad = BatchRow(group="x", sessions=[str(tmp_path / "x.h5")], error="cannot read x.h5")

    def progress(done: int, _total: int) -> None:
        if done == 1:  # a is in (progress counts the groups only)
            cluster.sync(worker.close, executor_wait=False, reason="test")

    with watching(label="cluster", worker_wait_s=1.0, poll_s=0.1, notify=lambda _: None), \
            pytest.raises(ClusterError) as err:
        fake_batch(["a_0", "b_block", "c_block"], client, rows=[bad], progress=progress)
    out = tmp_path / "out"
    assert str(err.value).endswith(
        f"; 1 finished group(s) kept in {out / 'summary.json'} and {out / 'summary.csv'}; "
        "2 group(s) not run: b, c"), str(err.value)
    assert _summary(out) == ["x", "a"]

def test_a_worker_that_joins_in_time_lets_the_batch_finish(
        fake_batch: Any, threads: tuple[Any, Any], tmp_path: Path) -> None:
    cluster, client = threads
    [worker] = cluster.workers.values()
    warnings: list[str] = []
    joined: list[Any] = []

    def notify(msg: str) -> None:
        warnings.append(msg)
        if "no workers" in msg:  # a new worker joins; the old one's tasks run there
            cluster_fakes.GATE.set()

            async def start() -> Any:
                return await distributed.Worker(cluster.scheduler_address, nthreads=1)

            joined.append(cluster.sync(start))

    def progress(done: int, _total: int) -> None:
        if done == 1:
            cluster.sync(worker.close, executor_wait=False, reason="test")

    try:
        with watching(label="cluster", worker_wait_s=30.0, poll_s=0.1, notify=notify):
            rows = fake_batch(["a_0", "b_block", "c_block"], client, progress=progress)
    finally:
        for w in joined:
            cluster.sync(w.close)
    assert [r.group for r in rows] == ["a", "b", "c"] and not any(r.error for r in rows)
    assert len(warnings) == 2 and warnings[1] == "cluster: 1 worker(s) again"


def test_batch_rows_in_input_order_with_each_groups_own_seconds(
        fake_batch: Any, threads: tuple[Any, Any], tmp_path: Path) -> None:
    """Two threads, five groups: ``a`` (1 s) ends last, after ``b`` to ``e`` (0.2 s each, one
    after another on the other thread: ``e`` waits 0.6 s for it). The rows still come as given,
    and ``e``'s seconds are its own 0.2 s, not the 0.8 s since it was submitted."""
    _, client = threads
    names = ["a_1.0", "b_0.2", "c_0.2", "d_0.2", "e_0.2"]
    rows = fake_batch(names, client)
    assert [r.group for r in rows] == _summary(tmp_path / "out") == ["a", "b", "c", "d", "e"]
    seconds = {r.group: r.seconds for r in rows}
    assert seconds["a"] >= 1.0 and all(seconds[g] >= 0.2 for g in "bcde")
    assert seconds["e"] < 0.6, seconds
    local = fake_batch(names, None)
    assert [r.group for r in local] == ["a", "b", "c", "d", "e"]
    for a, b in zip(local, rows, strict=True):
        assert (a.order, a.fit, a.error) == (b.order, b.fit, b.error)
        np.testing.assert_array_equal(a.poles, b.poles)


# ------------------------------------------------------------- a sweep's workers all leave
_DATA = {"data": np.arange(1000)}  # what run_pasts scatters; fake_past returns its sum
_SUM = int(np.arange(1000).sum())


def _data_left(n: int) -> str:
    return (f"cluster: the workers holding the sweep's data left; {n} past(s) to run again, "
            "the data sent again once a worker is there")


def _no_workers(address: str, wait_s: float) -> str:
    return (f"cluster: the scheduler has no workers; waiting up to {wait_s:g} s for one "
            f"(start one with `dask worker {address}`)")


def test_workers_lost_mid_sweep_a_worker_that_joins_runs_the_rest(
        threads: tuple[Any, Any]) -> None:
    """The only worker leaves once past 1 is in, with the sweep's scattered data: the
    scheduler (still running) cancels pasts 2 and 3. That is no lost scheduler: the sweep
    warns, waits for a worker, sends the data again and a worker that joins runs them."""
    cluster, client = threads
    [worker] = cluster.workers.values()
    address = cluster.scheduler_address
    results: dict[int, list[int]] = {}
    warnings: list[str] = []
    joined: list[Any] = []

    def finished(past: int, rows: list[int]) -> None:
        results[past] = rows
        if past == 1:  # the others still blocked on the worker that holds the data
            cluster.sync(worker.close, executor_wait=False, reason="test")

    def notify(msg: str) -> None:
        warnings.append(msg)
        if "no workers" in msg:
            joined.append(cluster_fakes.start_worker(cluster))
            cluster_fakes.GATE.set()  # the pasts run again do not block

    cluster_fakes.GATE.clear()
    t0 = time.monotonic()
    try:
        with watching(label="cluster", worker_wait_s=30.0, poll_s=0.1, notify=notify):
            run_pasts(client, task=cluster_fakes.fake_past, shared=_DATA,
                      common={"first": 1}, pasts=[1, 2, 3], finished=finished)
    finally:
        for w in joined:
            cluster.sync(w.close)
    assert time.monotonic() - t0 < DEADLINE_S
    assert results == {1: [1, _SUM], 2: [2, _SUM], 3: [3, _SUM]}
    # the loss and the empty scheduler may be seen in either order; the new worker after both
    assert sorted(warnings) == sorted([_data_left(2), _no_workers(address, 30.0),
                                       "cluster: 1 worker(s) again"]), warnings
    assert warnings[-1] == "cluster: 1 worker(s) again"
    assert len(joined) == 1


def test_workers_lost_mid_sweep_none_joins_is_the_worker_wait(
        threads: tuple[Any, Any]) -> None:
    """No worker joins: the sweep ends after the worker wait with that line, not with a lost
    scheduler (the scheduler still runs)."""
    cluster, client = threads
    [worker] = cluster.workers.values()
    address = cluster.scheduler_address
    warnings: list[str] = []

    def finished(past: int, _rows: Any) -> None:
        if past == 1:
            cluster.sync(worker.close, executor_wait=False, reason="test")

    cluster_fakes.GATE.clear()
    t0 = time.monotonic()
    # a worker wait of 5 s: the scheduler's cancellations (the "data left" warning) come
    # within it on a busy host too (with 1 s they could come after it)
    with watching(label="cluster", worker_wait_s=5.0, poll_s=0.1, notify=warnings.append), \
            pytest.raises(ClusterError) as err:
        run_pasts(client, task=cluster_fakes.fake_past, shared=_DATA, common={"first": 1},
                  pasts=[1, 2, 3], finished=finished)
    assert time.monotonic() - t0 < DEADLINE_S
    assert not isinstance(err.value, SchedulerLost)
    assert str(err.value) == (f"cluster: the scheduler had no workers for 5 s; start one with "
                              f"`dask worker {address}`")
    assert sorted(warnings) == sorted([_data_left(2), _no_workers(address, 5.0)]), warnings


def test_sweep_whose_data_keep_being_lost_ends_in_one_line(
        threads: tuple[Any, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    """Every worker leaves as soon as it has the data (a worker that keeps crashing), no past
    ever finishes: after RESEND_LIMIT losses in a row the sweep ends with one line."""
    cluster, client = threads
    real = sysid.cluster.runs.scatter
    scattered: list[int] = []
    joined: list[Any] = []

    def scatter_then_leave(*args: Any, **kwargs: Any) -> Any:
        handle = real(*args, **kwargs)
        scattered.append(1)
        for w in [*cluster.workers.values(), *joined]:
            cluster.sync(w.close, executor_wait=False, reason="test")
        return handle

    def notify(msg: str) -> None:
        if "no workers" in msg:
            joined.append(cluster_fakes.start_worker(cluster))

    monkeypatch.setattr(sysid.cluster.runs, "scatter", scatter_then_leave)  # run_pasts' call
    cluster_fakes.GATE.clear()
    t0 = time.monotonic()
    try:
        with watching(label="cluster", worker_wait_s=30.0, poll_s=0.1, notify=notify), \
                pytest.raises(DataLost) as err:
            run_pasts(client, task=cluster_fakes.fake_past, shared=_DATA,
                      common={"first": 0}, pasts=[1, 2], finished=lambda *_: None)
    finally:
        for w in joined:
            with contextlib.suppress(Exception):
                cluster.sync(w.close)
    assert time.monotonic() - t0 < DEADLINE_S
    assert str(err.value) == (f"cluster: the workers holding the sweep's data left "
                              f"{RESEND_LIMIT} times without a past finishing (2 past(s) not "
                              "run); run again when the workers stay")
    assert len(scattered) == RESEND_LIMIT


def test_result_not_handed_over_while_the_scheduler_answers_is_no_lost_scheduler(
        threads: tuple[Any, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    """A finished task whose result does not come within the limit (its worker left): the
    scheduler still answers, so the line says so, not "does not answer"."""
    _, client = threads
    monkeypatch.setenv(CONNECT_ENV, "0.1")

    class Late:
        status = "finished"

        def result(self, timeout: float) -> Any:
            raise TimeoutError

        def cancelled(self) -> bool:
            return False

    with watching(label="cluster"), pytest.raises(ClusterError) as err:
        task_result(client, Late())
    assert not isinstance(err.value, SchedulerLost)
    assert str(err.value) == ("cluster: a finished task's result was not handed over within "
                              "1 s (the worker holding it left?)")

def _finished_then_orphaned(cluster: Any, client: Any) -> Any:
    """A task that finished on the cluster's only worker, which then left before its result
    was fetched (the scheduler marks it lost and will run it again)."""
    fut = client.submit(int, 42, pure=False)
    deadline = time.monotonic() + DEADLINE_S
    while fut.status != "finished" and time.monotonic() < deadline:
        time.sleep(0.02)
    [worker] = cluster.workers.values()
    cluster.sync(worker.close, executor_wait=False, reason="test")
    while fut.status != "lost" and time.monotonic() < deadline:
        time.sleep(0.02)
    assert fut.status == "lost"
    return fut


def test_result_lost_with_its_worker_and_none_left_ends_at_the_worker_wait(
        threads: tuple[Any, Any], monkeypatch: pytest.MonkeyPatch) -> None:
    """Not at the result limit (ten connect timeouts: 100 s by default, 20 s here)."""
    cluster, client = threads
    monkeypatch.setenv(CONNECT_ENV, "2")
    fut = _finished_then_orphaned(cluster, client)
    warnings: list[str] = []
    t0 = time.monotonic()
    with watching(label="cluster", worker_wait_s=1.0, poll_s=0.1, notify=warnings.append), \
            pytest.raises(ClusterError) as err:
        task_result(client, fut)
    assert time.monotonic() - t0 < 15.0
    assert str(err.value).startswith("cluster: the scheduler had no workers for 1 s; ")
    assert warnings[0].startswith("cluster: the scheduler has no workers; waiting up to 1 s")


def test_result_lost_with_its_worker_is_computed_again_by_one_that_joins(
        threads: tuple[Any, Any]) -> None:
    cluster, client = threads
    fut = _finished_then_orphaned(cluster, client)
    joined: list[Any] = []

    def notify(msg: str) -> None:
        if "no workers" in msg:
            async def start() -> Any:
                return await distributed.Worker(cluster.scheduler_address, nthreads=1)

            joined.append(cluster.sync(start))

    try:
        with watching(label="cluster", worker_wait_s=30.0, poll_s=0.1, notify=notify):
            assert task_result(client, fut) == 42
    finally:
        for w in joined:
            cluster.sync(w.close)
    assert len(joined) == 1


@pytest.fixture
def killable() -> Iterator[tuple[subprocess.Popen[str], str]]:
    """A one-process cluster (:func:`tests.sysid.cluster_fakes.serve`) and its address."""
    proc = subprocess.Popen([sys.executable, "-m", "tests.sysid.cluster_fakes"], cwd=ROOT,
                            env=_env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        address = proc.stdout.readline().strip()
        assert address.startswith("tcp://127.0.0.1:"), address
        yield proc, address
    finally:
        proc.kill()
        proc.wait(timeout=30)


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
    batch = subprocess.Popen(cmd, cwd=ROOT, env=_env(), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
    try:
        while time.monotonic() - t0 < DEADLINE_S and batch.poll() is None:
            if (out / "summary.json").exists() and _summary(out):
                break
            time.sleep(0.05)
        server.kill()  # the scheduler (and its worker) die mid-batch
        _, stderr = batch.communicate(timeout=DEADLINE_S)
    finally:
        batch.kill()
    assert time.monotonic() - t0 < DEADLINE_S
    lines = _clean(stderr)
    assert lines[-1] == (
        f"error: --scheduler {address}: lost the connection to the scheduler; 1 finished "
        f"group(s) kept in {out / 'summary.json'} and {out / 'summary.csv'}; 2 group(s) not "
        "run: b_block, c_block"), stderr
    assert batch.returncode == 2
    assert not any("100 %" in line or "done" in line for line in lines)
    assert _summary(out) == ["a_0"]


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


# ------------------------------------------------------- a scheduler that stops answering
def _stop(server: subprocess.Popen[str]) -> None:
    """The scheduler's process stops (SIGSTOP): its connections stay open and the system still
    accepts new ones, but nothing answers (a hung scheduler; the fixture kills it). Returns
    once every thread of it is stopped: the signal is delivered asynchronously, and on a busy
    host a thread still running answered one more request (the dashboard's, seen once in two
    runs beside a second test run)."""
    os.kill(server.pid, signal.SIGSTOP)
    deadline = time.monotonic() + 30.0
    tasks = Path(f"/proc/{server.pid}/task")
    while tasks.is_dir() and time.monotonic() < deadline:
        states = []
        for stat in tasks.glob("*/stat"):
            with contextlib.suppress(OSError):  # a thread that ended meanwhile
                states.append(stat.read_text().rsplit(")", 1)[1].split()[0])
        if states and all(state in "Tt" for state in states):
            return
        time.sleep(0.005)


def test_scheduler_that_stops_answering_before_the_client_starts_is_one_line(
        killable: tuple[subprocess.Popen[str], str], session: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """It answers the handshake check, then nothing: ``distributed.Client`` would wait for its
    own handshake forever; the command ends within the connect timeout."""
    server, address = killable
    real = sysid.cluster.connection.probe

    def probe_then_stop(*args: Any, **kwargs: Any) -> str | None:
        problem = real(*args, **kwargs)
        _stop(server)
        return problem

    monkeypatch.setattr(sysid.cluster.connection, "probe", probe_then_stop)  # connect()'s call
    monkeypatch.setenv(CONNECT_ENV, str(CONNECT_S))
    before = set(threading.enumerate())
    res, took = _cli(*_sweep_args(session, address))
    assert res.exit_code == 2, res.output
    assert _clean(res.stderr) == [f"error: --scheduler {address}: the scheduler does not "
                                  f"answer (the client did not start within {CONNECT_S:g} s)"]
    assert took < DEADLINE_S
    assert server.poll() is None  # still there, stopped: nothing closed the connection
    # the half-started client was closed: no thread of it is left behind
    deadline = time.monotonic() + DEADLINE_S
    while set(threading.enumerate()) - before and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not set(threading.enumerate()) - before


def test_scheduler_that_stops_answering_during_the_scatter_is_one_line(
        killable: tuple[subprocess.Popen[str], str], session: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The sweep's one-time scatter of its data: the scheduler stops as it begins."""
    server, address = killable
    real = distributed.Client.scatter
    calls: list[dict[str, Any]] = []

    def stop_then_scatter(self: Any, *args: Any, **kwargs: Any) -> Any:
        calls.append(kwargs)
        _stop(server)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(distributed.Client, "scatter", stop_then_scatter)
    monkeypatch.setenv(CONNECT_ENV, str(CONNECT_S))
    res, took = _cli(*_sweep_args(session, address))
    assert res.exit_code == 2, res.output
    lines = _clean(res.stderr)
    assert lines[0].startswith(f"dask: {address}, 1 worker(s)")
    assert lines[-1] == (f"error: --scheduler {address}: the scheduler does not answer "
                         f"(waited {CONNECT_S:g} s)")
    assert took < DEADLINE_S
    assert len(calls) == 1 and calls[0]["broadcast"] is True  # it was the scatter that waited


def test_scheduler_that_stops_answering_once_connected_is_one_line(
        killable: tuple[subprocess.Popen[str], str], session: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The command's first question once connected (the dashboard's address:
    ``Client.dashboard_link`` would wait without a limit)."""
    server, address = killable
    real = sysid.cluster.connect

    def connect_then_stop(*args: Any, **kwargs: Any) -> Any:
        client = real(*args, **kwargs)
        _stop(server)
        return client

    monkeypatch.setattr(sysid.cluster, "connect", connect_then_stop)  # the CLI imports it here
    monkeypatch.setenv(CONNECT_ENV, str(CONNECT_S))
    res, took = _cli(*_sweep_args(session, address))
    assert res.exit_code == 2, res.output
    assert _clean(res.stderr) == [f"error: --scheduler {address}: the scheduler does not "
                                  f"answer (waited {CONNECT_S:g} s)"]
    assert took < DEADLINE_S


def test_dashboard_link_from_the_schedulers_answer() -> None:
    class Fake:
        def __init__(self, services: dict[str, int], address: str) -> None:
            self.services = services
            self.scheduler = type("Rpc", (), {"address": address, "identity": None})()

        def sync(self, *_: Any, **kwargs: Any) -> dict[str, Any]:
            assert kwargs["callback_timeout"] > 0  # never an unbounded wait
            return {"services": self.services}

    assert dashboard_link(Fake({}, "tcp://10.0.0.5:8786")) is None
    assert dashboard_link(Fake({"dashboard": 8787}, "tcp://10.0.0.5:8786")) == \
        "http://10.0.0.5:8787/status"
    assert dashboard_link(Fake({"dashboard": 8787}, "tcp://[::1]:8786")) == \
        "http://[::1]:8787/status"


def test_scatter_that_never_ends_is_cancelled_at_its_limit(
        threads: tuple[Any, Any]) -> None:
    """A scheduler that answers but never finishes the scatter (a worker that does not take
    its copy): a one-line error at the limit, the scatter cancelled."""
    _, client = threads
    cancelled = threading.Event()

    async def forever() -> Any:
        try:
            await asyncio.sleep(3600)
        finally:
            cancelled.set()

    class Stuck:
        def scatter(self, *_: Any, **kwargs: Any) -> Any:
            assert kwargs["asynchronous"] is True
            return forever()

        def __getattr__(self, name: str) -> Any:
            return getattr(client, name)

    t0 = time.monotonic()
    with watching(label="cluster", poll_s=0.1), \
            pytest.raises(ClusterError) as err:
        scatter(Stuck(), {"x": 1}, limit_s=0.5)
    assert str(err.value) == ("cluster: the data were not sent to the workers within 0.5 s "
                              "(a worker that does not answer?)")
    assert not isinstance(err.value, SchedulerLost)
    assert cancelled.wait(DEADLINE_S) and time.monotonic() - t0 < DEADLINE_S
    # the real one, on the same client, still works
    assert client.gather(scatter(client, {"x": 1})) == {"x": 1}


# ----------------------------------------------------- workers killed while running a task
@pytest.fixture
def four() -> Iterator[tuple[Any, Any]]:
    """A scheduler with four one-thread workers in this process (Dask's default
    allowed-failures, 3, lets a task lose four); a client of it."""
    cluster = distributed.LocalCluster(n_workers=4, threads_per_worker=1, processes=False,
                                       protocol="tcp://", host="127.0.0.1",
                                       dashboard_address="127.0.0.1:0")
    client = distributed.Client(cluster.scheduler_address, timeout=10)
    cluster_fakes.LOSE.clear()
    yield cluster, client
    cluster_fakes.LOSE.set()
    cluster_fakes.GATE.set()
    client.close(timeout=10)
    cluster.close(timeout=10)


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
                            env=_env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        address = proc.stdout.readline().strip()
        assert address.startswith("tcp://127.0.0.1:"), address
        path = write_flight(tmp_path / "k_die.h5", system=known_system(), seed=3, n=1200).path
        out = tmp_path / "out"
        batch, took = _sysid("batch", path, "--out", out, "--order", "4", "--past", "5",
                             "--future", "5", "--scheduler", address)
    finally:
        proc.kill()
        proc.wait(timeout=30)
    assert batch.returncode == 2, batch.stderr
    lines = _clean(batch.stderr)
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
