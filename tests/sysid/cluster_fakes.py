"""Stand-ins for the Dask fault tests (``tests/sysid/cluster_faults/``).

- :func:`fake_identify` replaces :func:`sysid.batch.identify_group`: it takes as long as its
  session's name says (``a_0.5.h5``: 0.5 s; ``b_block.h5``: until :data:`GATE` opens, at most
  :data:`BLOCK_S`, then :data:`AFTER_S`; ``k_die.h5``: its worker is lost, see
  :func:`lose_worker`) and returns a fixed model;
- :func:`fake_past` is a sweep task (:func:`sysid.cluster.run_pasts`) that blocks for every
  past but the first, and loses its worker for the past ``die``; :func:`start_worker` adds a
  worker to an in-process cluster;
- ``python -m tests.sysid.cluster_fakes [N]`` runs a scheduler with N (default 1) one-thread
  workers in a process of its own (batch groups identified by :func:`fake_identify`), prints
  its address and serves until its stdin closes, so a test can stop or kill it mid-run.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path
from typing import Any

#: Opened by a test to release the blocked tasks of this process.
GATE = threading.Event()
#: Longest a blocked task waits.
BLOCK_S = 30.0
#: How long a blocked group still takes once :data:`GATE` is open.
AFTER_S = 0.5
#: A task that loses its worker (:func:`lose_worker`) first waits for this (open unless a test
#: closes it).
LOSE = threading.Event()
LOSE.set()


def _stem(groups: list[list[Any]]) -> str:
    return Path(groups[0][0].source.partition("#")[0]).stem


def fake_identify(groups: list[list[Any]], **_: Any) -> dict[str, Any]:
    """What :func:`sysid.batch.identify_group` returns, after the delay the name gives."""
    from tests.sysid.flights import known_system

    delay = _stem(groups).rpartition("_")[2]
    if delay == "die":
        lose_worker()
    if delay == "block":
        GATE.wait(BLOCK_S)
        time.sleep(AFTER_S)
    elif delay:
        time.sleep(float(delay))
    model = known_system()
    return {"model": model, "past": 2, "future": 3, "order": model.n_states,
            "focus": "prediction", "method": "iem", "fit": [90.0], "score": 90.0,
            "stable": True, "outputs": ["gyro.x"], "warnings": []}


def fake_past(*, past: int, first: int, die: int | None = None, data: Any = None,
              **_: Any) -> list[Any]:
    """A sweep task: ``first`` returns at once, every other past blocks (:data:`GATE`); the
    past ``die`` loses its worker (:func:`lose_worker`). Returns ``[past]``, and the sum of
    the shared ``data`` when given (so a test sees the scattered data reached the task)."""
    if past == die:
        lose_worker()
    if past != first:
        GATE.wait(BLOCK_S)
    return [past] if data is None else [past, int(sum(data))]


def start_worker(cluster: Any) -> Any:
    """A new one-thread worker of ``cluster`` (in this process), registered when this returns;
    close it with ``cluster.sync(worker.close)``."""
    import distributed

    async def start() -> Any:
        return await distributed.Worker(cluster.scheduler_address, nthreads=1)

    return cluster.sync(start)


def lose_worker() -> None:
    """Called in a task: once :data:`LOSE` is open, the worker running it closes at once, as
    if its process were killed (the scheduler counts the task as suspicious and runs it on
    another worker, up to its ``allowed-failures``), and the task blocks until :data:`GATE`
    opens."""
    from distributed import get_worker

    LOSE.wait(BLOCK_S)
    worker = get_worker()
    worker.loop.add_callback(worker.close, executor_wait=False, reason="test: worker lost")
    GATE.wait(BLOCK_S)
    raise RuntimeError("the lost worker's task went on")  # never seen: its worker is gone


def serve() -> None:
    import distributed

    import sysid.batch

    sysid.batch.identify_group = fake_identify  # type: ignore[assignment]
    n_workers = int(sys.argv[1]) if len(sys.argv) > 1 else 1
    cluster = distributed.LocalCluster(n_workers=n_workers, threads_per_worker=1,
                                       processes=False, protocol="tcp://", host="127.0.0.1",
                                       dashboard_address="127.0.0.1:0")
    print(cluster.scheduler_address, flush=True)
    sys.stdin.read()  # until the test closes it (or kills this process)
    GATE.set()
    cluster.close(timeout=10)


if __name__ == "__main__":
    serve()
