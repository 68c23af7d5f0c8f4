"""Running sweeps and batches on an existing Dask distributed cluster (optional extra).

``pip install cf-sysid[dask]`` installs ``dask[distributed]``; without it, asking for a
cluster raises :class:`~sysid.errors.MissingDependencyError` with one line naming the extra.

**What is sent.** A sweep's data products (the grid's Gram matrix with its flights, and the
validation records) are scattered to every worker (``client.scatter(..., broadcast=True)``;
again when the workers holding them leave: :mod:`sysid.cluster.runs`);
each task then carries only its past (an integer) and the small method/options objects, and
returns its rows. The workers run the same :func:`sysid.sweep._past_task` as the local worker
processes, on the same arrays, so the rows are the same. A batch sends each group's records
with that group's one task (they are needed by one worker only).

**Faults.** Every wait on the cluster is bounded, and each fault is one
:class:`~sysid.errors.ClusterError` line; each module lists the faults of its part:

- :mod:`sysid.cluster.connection`, reaching the scheduler: :func:`connect` checks its Dask
  handshake within the connect timeout before the client starts, and bounds that start;
  the optional extra (:func:`require_distributed`), the two waits, Dask's own log;
- :mod:`sysid.cluster.watch`, asking it during a command (:func:`watching`): every request
  that waits for its answer gets the connect timeout (:class:`SchedulerLost`), a scheduler
  without workers is warned of and ends the run after the worker wait;
- :mod:`sysid.cluster.runs`, running on it: tasks as they end (:func:`completed`), their
  results (:func:`task_result`: a worker killed running a task is :class:`WorkerLost`, that
  task's failure), a sweep's data scattered once (:func:`scatter`) and, lost with the workers
  holding them, sent again (:func:`run_pasts`, :class:`DataLost`).

The two waits default to :data:`CONNECT_TIMEOUT_S` and :data:`WORKER_WAIT_S`; the
environment variables :data:`CONNECT_ENV` and :data:`WORKER_WAIT_ENV` (seconds) replace them.

The names below are the interface (``from sysid.cluster import connect``): the same objects as
in their modules. The modules call each other's functions through their own imports, so a test
that replaces one (``monkeypatch``) replaces it in the module whose code calls it
(``sysid.cluster.connection.probe``, called by :func:`connect`), not here.
"""

from __future__ import annotations

from sysid.cluster.connection import (
    CONNECT_ENV,
    CONNECT_TIMEOUT_S,
    EXTRA_HINT,
    WORKER_WAIT_ENV,
    WORKER_WAIT_S,
    connect,
    connect_timeout_s,
    probe,
    quiet_dask_log,
    require_distributed,
    worker_wait_s,
)
from sysid.cluster.runs import (
    RESEND_LIMIT,
    DataLost,
    TaskCancelled,
    WorkerLost,
    cancel_quietly,
    completed,
    run_pasts,
    scatter,
    task_result,
)
from sysid.cluster.runs import RESULT_WAITS as RESULT_WAITS
from sysid.cluster.watch import (
    POLL_S,
    SchedulerLost,
    Watch,
    WorkerWatch,
    dashboard_link,
    wait_for_workers,
    watching,
    worker_count,
)

__all__ = ["CONNECT_ENV", "CONNECT_TIMEOUT_S", "EXTRA_HINT", "POLL_S", "RESEND_LIMIT",
           "WORKER_WAIT_ENV", "WORKER_WAIT_S", "DataLost", "SchedulerLost", "TaskCancelled",
           "Watch", "WorkerLost", "WorkerWatch", "cancel_quietly",
           "completed", "connect", "connect_timeout_s", "dashboard_link", "probe",
           "quiet_dask_log", "require_distributed", "run_pasts", "scatter", "task_result",
           "wait_for_workers", "watching", "worker_count", "worker_wait_s"]
