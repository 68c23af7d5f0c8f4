"""Workers lost mid-run: a batch warns and ends keeping its finished groups, a worker that
joins in time lets it finish; a sweep whose workers all leave sends its data again to one that
joins or ends at the worker wait; a result lost with its worker is computed again. And a
batch on the cluster gives the local batch's rows: in input order, each group's own time."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sysid.cluster
import sysid.cluster.runs
from sysid.batch import BatchRow
from sysid.cluster import (
    CONNECT_ENV,
    RESEND_LIMIT,
    DataLost,
    SchedulerLost,
    run_pasts,
    task_result,
    watching,
)
from sysid.errors import ClusterError
from tests.sysid import cluster_fakes
from tests.sysid.cluster_faults.support import (
    DEADLINE_S,
    summary,
)

distributed = pytest.importorskip("distributed")


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
    assert summary(tmp_path / "out") == ["a"]  # the not-run groups are no failed rows


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
    assert summary(out) == ["x", "a"]

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
    assert [r.group for r in rows] == summary(tmp_path / "out") == ["a", "b", "c", "d", "e"]
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


