"""Running on the cluster: a batch's tasks as they end (:func:`completed`,
:func:`task_result`, :func:`cancel_quietly`) and a sweep's pasts on the data scattered to
every worker (:func:`run_pasts`, :func:`scatter`). The cluster is checked every
:data:`~sysid.cluster.watch.POLL_S` meanwhile, and each fault is one
:class:`~sysid.errors.ClusterError` line:

- a sweep's one-time scatter checks every :data:`~sysid.cluster.watch.POLL_S` that the
  scheduler still answers and ends within :data:`RESULT_WAITS` connect timeouts;
- :func:`completed` yields the tasks as they end and checks the cluster every
  :data:`~sysid.cluster.watch.POLL_S`: a lost scheduler connection ends the run at once
  (:class:`~sysid.cluster.watch.SchedulerLost`), a scheduler without workers is reported
  through the :func:`~sysid.cluster.watch.watching` ``notify`` and ends the run when no
  worker has joined within the worker wait. A task cancelled while the scheduler still
  answers is no lost scheduler: :class:`TaskCancelled` (a batch), or handed to the caller
  (a sweep, below);
- a sweep's scattered data live only on the workers: when every worker holding them leaves,
  the scheduler forgets them and cancels the pasts that need them (finished ones whose
  results were not fetched yet too). :func:`run_pasts` then waits for a worker as above (the
  same warning and worker wait), sends the data again and reruns those pasts; after
  :data:`RESEND_LIMIT` such losses in a row without a past finishing it ends with one line
  (:class:`DataLost`);
- :func:`task_result` turns Dask's ``KilledWorker`` (the workers running a task died more
  often than the scheduler's ``allowed-failures``) into a one-line :class:`WorkerLost`: a
  failure of that task (a batch's failed row), not of the cluster. A finished task whose
  worker left before its result was fetched is run again by the scheduler and waited for as a
  running task is (the run's :class:`~sysid.cluster.watch.WorkerWatch` carries the no-worker
  wait).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any

from sysid.cluster.connection import connect_timeout_s, require_distributed
from sysid.cluster.watch import (
    SchedulerLost,
    WorkerWatch,
    _label,
    _lost,
    _no_worker_hint,
    _watch,
    worker_count,
)
from sysid.errors import ClusterError, SysIdError, first_line

__all__ = ["RESEND_LIMIT", "RESULT_WAITS", "DataLost", "TaskCancelled", "WorkerLost",
           "cancel_quietly", "completed", "run_pasts", "scatter", "task_result"]

log = logging.getLogger("sysid.cluster")  # the package's one logger

#: A finished task's result (rows, a model: small) is fetched, and a sweep's data are sent
#: to the workers, within this many connect timeouts.
RESULT_WAITS = 10
#: A sweep ends (:class:`DataLost`) when its data were lost this many times in a row without
#: a past finishing in between (workers that keep leaving).
RESEND_LIMIT = 3
#: How long the result loop sleeps between looks at finished tasks.
_TICK_S = 0.02


class TaskCancelled(ClusterError):
    """A task was cancelled on the cluster while the scheduler still answers (not a lost
    scheduler): the data it needs were lost with the workers that held them, or another
    client cancelled it."""


class DataLost(ClusterError):
    """A sweep's data were lost with the workers holding them too often in a row
    (:data:`RESEND_LIMIT`) for the sweep to go on."""


class WorkerLost(SysIdError):
    """The workers running one task died more often than the scheduler allows (Dask's
    ``KilledWorker``): that task failed, the cluster goes on (no :class:`ClusterError`)."""


def _cancel_reason(future: Any) -> str:
    reason = getattr(getattr(getattr(future, "_state", None), "exception", None), "reason", None)
    return str(reason) if reason else "no reason given"


def _cancelled(client: Any, future: Any, label: str) -> TaskCancelled:
    """A cancelled ``future``: :class:`SchedulerLost` raised when the client lost the
    scheduler (it cancels every task then) or the scheduler does not answer, else the
    :class:`TaskCancelled` to raise or handle."""
    worker_count(client, label=label)  # SchedulerLost unless running and answering
    return TaskCancelled(f"{label}: the scheduler cancelled a task while it still answers "
                         f"({_cancel_reason(future)})")


def completed(client: Any, futures: Iterable[Any], *,
              cancelled: Callable[[Any], None] | None = None,
              workers: WorkerWatch | None = None) -> Iterator[Any]:
    """Yield ``futures`` as they finish, like ``distributed.as_completed``, watching the
    cluster meanwhile (:func:`watching`): :class:`SchedulerLost` as soon as the scheduler
    connection is lost (its tasks are cancelled with it), a warning when the scheduler has no
    workers and a :class:`ClusterError` when none has joined within the worker wait.

    A future cancelled while the scheduler still answers is given to ``cancelled`` (not
    yielded), or, without it, ends the run with :class:`TaskCancelled`. ``workers`` carries
    the no-worker wait over from an earlier call of the same run."""
    distributed = require_distributed()
    watch = _watch()
    label = _label(client, watch)
    workers = workers or WorkerWatch(client, watch)
    pending = distributed.as_completed(list(futures), loop=client.loop)
    next_check = time.monotonic() + watch.poll_s
    while not pending.is_empty():
        if pending.has_ready():
            gone: list[Any] = []
            ended: list[Any] = []
            for fut in pending.next_batch(block=False):
                (gone if fut.cancelled() else ended).append(fut)
            if gone:  # the client cancels every task when it loses the scheduler: ask it
                exc = _cancelled(client, gone[0], label)  # (once for the batch)
                if cancelled is None:
                    raise exc
                for fut in gone:
                    cancelled(fut)
            yield from ended
            continue
        time.sleep(_TICK_S)
        if time.monotonic() < next_check:
            continue
        workers.check()
        next_check = time.monotonic() + watch.poll_s


def task_result(client: Any, future: Any, *, workers: WorkerWatch | None = None) -> Any:
    """``future.result()``: the task's value, or the exception the task raised; a
    :class:`SchedulerLost` when the result could not be fetched because the scheduler went
    away meanwhile (the connection closed or reset, the future cancelled with it) or did not
    hand it over within :data:`RESULT_WAITS` connect timeouts and does not answer now;
    :class:`TaskCancelled` when the future was cancelled while the scheduler still answers
    (its result was lost with the workers holding it, and so was the data it needs); a
    :class:`ClusterError` when the result did not come in that time but the scheduler
    answers.

    A finished task whose worker left before its result was fetched is run again by the
    scheduler (its future goes back to pending): that is waited for as a running task is,
    with the cluster checked every :data:`POLL_S` (``workers``, a :class:`WorkerWatch`
    carrying the run's no-worker wait), so a cluster left without workers ends the run
    after the worker wait, not after the result limit."""
    watch = _watch()
    workers = workers or WorkerWatch(client, watch)
    limit = RESULT_WAITS * connect_timeout_s()
    deadline = time.monotonic() + limit
    while True:
        try:
            return future.result(timeout=max(min(watch.poll_s, deadline - time.monotonic()),
                                             0.0))
        except (Exception, asyncio.CancelledError) as exc:
            lost = _worker_lost(exc)
            if lost is not None:
                raise lost from None
            if future.status == "error" or not isinstance(
                    exc, (OSError, TimeoutError, concurrent.futures.CancelledError,
                          asyncio.CancelledError)):
                raise  # the task's own failure, or its result does not load here
            label = _label(client, watch)
            if future.cancelled():
                raise _cancelled(client, future, label) from None
            if not isinstance(exc, TimeoutError):
                raise _lost(client, label) from None
        workers.check()  # SchedulerLost, or the end of the worker wait
        now = time.monotonic()
        if future.status in ("pending", "lost"):  # run again (its worker left): not late
            deadline = now + limit
        elif now >= deadline:  # no lost scheduler: it answered just now
            raise ClusterError(f"{label}: a finished task's result was not handed over within "
                               f"{limit:g} s (the worker holding it left?)")


def _worker_lost(exc: BaseException) -> WorkerLost | None:
    """:class:`WorkerLost` (one line) for Dask's ``KilledWorker``, else None."""
    try:
        from distributed.scheduler import KilledWorker
    except ImportError:  # pragma: no cover - distributed without its scheduler
        return None
    if not isinstance(exc, KilledWorker):
        return None
    allowed = getattr(exc, "allowed_failures", None)
    where = getattr(getattr(exc, "last_worker", None), "address", None)
    times = f" {allowed + 1} times" if isinstance(allowed, int) else ""
    detail = "; ".join(x for x in (
        f"the scheduler's allowed-failures is {allowed}" if isinstance(allowed, int) else "",
        f"the last was {where}, see its log" if where else "see the workers' logs") if x)
    return WorkerLost(f"worker lost{times} while running it ({detail})")


def cancel_quietly(client: Any, futures: Iterable[Any], exc: BaseException | None) -> None:
    """Cancel ``futures`` on the cluster unless the scheduler is gone (``exc`` is
    :class:`SchedulerLost`, or the client is no longer running): nothing to cancel there,
    and asking would wait for the connect timeout."""
    if isinstance(exc, SchedulerLost) or client.status != "running":
        return
    with contextlib.suppress(Exception):
        client.cancel(list(futures))


# --------------------------------------------------------------------------------- sweeps
def run_pasts(client: Any, *, task: Callable[..., Any], shared: dict[str, Any],
              common: dict[str, Any], pasts: Iterable[int],
              finished: Callable[[int, Any], None]) -> None:
    """Run ``task(past=p, **shared, **common)`` for every past on the cluster.

    ``shared`` (the large data products) is scattered once to every worker (:func:`scatter`:
    bounded); ``finished(p, result)`` is called here as each past ends. On any exception here
    (Ctrl-C included) the pending tasks are cancelled before it propagates; faults of the
    cluster are one-line :class:`ClusterError` (:func:`completed`), and so is a past whose
    workers died more often than the scheduler allows (:class:`WorkerLost`): the sweep needs
    every past.

    The scattered data are lost when every worker holding them leaves: the scheduler cancels
    the pasts not yet fetched (:class:`TaskCancelled`, the scheduler still answering). Those
    pasts are run again: once a worker is there (the :func:`watching` warning and worker wait,
    as for a scheduler without workers) the data are scattered again and the pasts
    resubmitted, announced through ``notify``. :data:`RESEND_LIMIT` losses in a row without
    a past finishing end the sweep (:class:`DataLost`)."""
    watch = _watch()
    label = _label(client, watch)
    say = watch.notify or log.warning
    workers = WorkerWatch(client, watch)
    todo = list(pasts)
    handles: list[Any] = []
    futures: dict[Any, int] = {}
    failure: BaseException | None = None
    losses = 0  # data losses since the last past finished
    try:
        while todo:
            handle = _scatter_when_workers(client, shared, label, workers, resend=bool(handles))
            handles.append(handle)
            futures = {client.submit(_with_shared, task, handle, past=p, pure=False,
                                     **common): p for p in todo}
            lost: set[Any] = set()
            for fut in completed(client, futures, cancelled=lost.add, workers=workers):
                try:
                    result = task_result(client, fut, workers=workers)
                except TaskCancelled:  # finished, its result lost before it was fetched
                    lost.add(fut)
                    continue
                except WorkerLost as exc:
                    raise ClusterError(f"{label}: past {futures[fut]}: {exc}") from None
                finished(futures[fut], result)
                losses = 0
            todo = [p for fut, p in futures.items() if fut in lost]
            if not todo:
                break
            losses += 1
            if losses >= RESEND_LIMIT:
                raise DataLost(f"{label}: the workers holding the sweep's data left {losses} "
                               f"times without a past finishing ({len(todo)} past(s) not "
                               "run); run again when the workers stay")
            say(f"{label}: the workers holding the sweep's data left; {len(todo)} past(s) "
                "to run again, the data sent again once a worker is there")
    except BaseException as exc:
        failure = exc
        cancel_quietly(client, futures, exc)
        raise
    finally:
        cancel_quietly(client, handles, failure)


def _scatter_when_workers(client: Any, shared: dict[str, Any], label: str,
                          workers: WorkerWatch, *, resend: bool) -> Any:
    """:func:`scatter` of a sweep's data; when sending it again (``resend``), first waited for
    a worker (bounded by the worker wait) and, should the scatter fail because the workers
    left again meanwhile, waited for again."""
    while True:
        if resend:
            workers.until_one()
        try:
            return scatter(client, shared, label=label)
        except SchedulerLost:
            raise
        except ClusterError:
            if not resend or workers.check():
                raise
            # the workers left during the scatter: wait for one again (the same wait)


def scatter(client: Any, data: Any, *, label: str | None = None,
            limit_s: float | None = None) -> Any:
    """``client.scatter([data], broadcast=True)``'s one future, or a one-line
    :class:`ClusterError`.

    ``Client.scatter`` waits for the scheduler's answer without a limit, and a large scatter to
    many workers may take long on a healthy cluster; so the scatter runs on the client's loop
    while this thread checks every :data:`POLL_S` (:func:`watching`) that the scheduler still
    answers (:func:`worker_count`, within the connect timeout: :class:`SchedulerLost`), and
    gives up after ``limit_s`` (default :data:`RESULT_WAITS` connect timeouts: a worker that
    does not take its copy). The scatter is cancelled on the way out."""
    watch = _watch()
    label = label or _label(client, watch)
    limit = RESULT_WAITS * connect_timeout_s() if limit_s is None else limit_s
    try:
        coro = client.scatter([data], broadcast=True, hash=False, asynchronous=True)
        running = asyncio.run_coroutine_threadsafe(coro, client.loop.asyncio_loop)
    except Exception as exc:  # the client closed under us
        raise _scatter_error(client, label, exc) from None
    deadline = time.monotonic() + limit
    try:
        while True:
            concurrent.futures.wait([running], timeout=min(
                watch.poll_s, max(deadline - time.monotonic(), 0.0)))
            if running.done():
                break
            if time.monotonic() >= deadline:
                raise ClusterError(f"{label}: the data were not sent to the workers within "
                                   f"{limit:g} s (a worker that does not answer?)")
            worker_count(client, label=label)  # SchedulerLost when it does not answer
    except BaseException:
        running.cancel()
        raise
    try:
        [handle] = running.result()
    except (Exception, asyncio.CancelledError) as exc:
        raise _scatter_error(client, label, exc) from None
    return handle


def _scatter_error(client: Any, label: str, exc: BaseException) -> ClusterError:
    if client.status != "running":
        return _lost(client, label)
    if "no valid workers" in str(exc).lower():
        return ClusterError(f"{label}: the scheduler has no workers to send the data to; "
                            f"{_no_worker_hint(client)}")
    return ClusterError(f"{label}: cannot send the data to the workers ({first_line(exc)})")


def _with_shared(task: Callable[..., Any], shared: dict[str, Any], **kwargs: Any) -> Any:
    return task(**shared, **kwargs)
