"""Stand-ins for the Dask fault tests (``test_cluster_faults.py``).

- :func:`fake_identify` replaces :func:`sysid.batch.identify_group`: it takes as long as its
  session's name says (``a_0.5.h5``: 0.5 s; ``b_block.h5``: until :data:`GATE` opens, at most
  :data:`BLOCK_S`, then :data:`AFTER_S`) and returns a fixed model;
- :func:`fake_past` is a sweep task (:func:`sysid.cluster.run_pasts`) that blocks for every
  past but the first;
- ``python -m tests.sysid.cluster_fakes`` runs a scheduler with one worker thread in a process
  of its own (batch groups identified by :func:`fake_identify`), prints its address and serves
  until its stdin closes, so a test can kill it mid-run.
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


def _stem(groups: list[list[Any]]) -> str:
    return Path(groups[0][0].source.partition("#")[0]).stem


def fake_identify(groups: list[list[Any]], **_: Any) -> dict[str, Any]:
    """What :func:`sysid.batch.identify_group` returns, after the delay the name gives."""
    from tests.sysid.flights import known_system

    delay = _stem(groups).rpartition("_")[2]
    if delay == "block":
        GATE.wait(BLOCK_S)
        time.sleep(AFTER_S)
    elif delay:
        time.sleep(float(delay))
    model = known_system()
    return {"model": model, "past": 2, "future": 3, "order": model.n_states,
            "focus": "prediction", "method": "iem", "fit": [90.0], "score": 90.0,
            "stable": True}


def fake_past(*, past: int, first: int, **_: Any) -> list[int]:
    """A sweep task: ``first`` returns at once, every other past blocks (:data:`GATE`)."""
    if past != first:
        GATE.wait(BLOCK_S)
    return [past]


def serve() -> None:
    import distributed

    import sysid.batch

    sysid.batch.identify_group = fake_identify  # type: ignore[assignment]
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                       protocol="tcp://", host="127.0.0.1",
                                       dashboard_address="127.0.0.1:0")
    print(cluster.scheduler_address, flush=True)
    sys.stdin.read()  # until the test closes it (or kills this process)
    GATE.set()
    cluster.close(timeout=10)


if __name__ == "__main__":
    serve()
