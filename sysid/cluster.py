"""Running sweeps and batches on an existing Dask distributed cluster (optional extra).

``pip install cf-sysid[dask]`` installs ``dask[distributed]``; without it, asking for a
cluster raises :class:`~sysid.errors.MissingDependencyError` with one line naming the extra.

**What is sent.** A sweep's data products (the grid's Gram matrix with its flights, and the
validation records) are scattered to every worker (``client.scatter(..., broadcast=True)``;
again when the workers holding them leave: **Faults** below);
each task then carries only its past (an integer) and the small method/options objects, and
returns its rows. The workers run the same :func:`sysid.sweep._past_task` as the local worker
processes, on the same arrays, so the rows are the same. A batch sends each group's records
with that group's one task (they are needed by one worker only).

**Faults.** Every wait on the cluster is bounded, and each fault is one
:class:`~sysid.errors.ClusterError` line:

- :func:`connect` first opens a connection itself and reads the scheduler's Dask handshake,
  each step within the connect timeout (``distributed.Client`` waits for that answer without
  a limit): an address that accepts but never answers, or answers something other than Dask
  (an HTTP server, the dashboard's port), is refused within that time. The client's own
  start (its connection, handshake and registration) is bounded by the connect timeout too,
  so a scheduler that stops answering after that check is refused as well;
- every request that waits for the scheduler's answer (:func:`dashboard_link`,
  :func:`worker_count`) gets the connect timeout; a sweep's one-time scatter checks every
  :data:`POLL_S` that the scheduler still answers and ends within :data:`RESULT_WAITS`
  connect timeouts;
- :func:`completed` yields the tasks as they end and checks the cluster every
  :data:`POLL_S`: a lost scheduler connection ends the run at once (:class:`SchedulerLost`),
  a scheduler without workers is reported through the :func:`watching` ``notify`` and ends
  the run when no worker has joined within the worker wait. A task cancelled while the
  scheduler still answers is no lost scheduler: :class:`TaskCancelled` (a batch), or handed
  to the caller (a sweep, below);
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
  running task is (the run's :class:`WorkerWatch` carries the no-worker wait).

The two waits default to :data:`CONNECT_TIMEOUT_S` and :data:`WORKER_WAIT_S`; the
environment variables :data:`CONNECT_ENV` and :data:`WORKER_WAIT_ENV` (seconds) replace them.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import math
import os
import time
from collections.abc import Callable, Iterable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

from sysid.errors import (
    ClusterError,
    MissingDependencyError,
    ParameterError,
    SysIdError,
    first_line,
)

__all__ = ["CONNECT_ENV", "CONNECT_TIMEOUT_S", "EXTRA_HINT", "POLL_S", "RESEND_LIMIT",
           "WORKER_WAIT_ENV", "WORKER_WAIT_S", "DataLost", "SchedulerLost", "TaskCancelled",
           "Watch", "WorkerLost", "WorkerWatch", "cancel_quietly",
           "completed", "connect", "connect_timeout_s", "dashboard_link", "probe",
           "quiet_dask_log", "require_distributed", "run_pasts", "scatter", "task_result",
           "wait_for_workers", "watching", "worker_count", "worker_wait_s"]

log = logging.getLogger(__name__)

EXTRA_HINT = "dask.distributed is not installed; install the extra: pip install 'cf-sysid[dask]'"

#: Seconds to reach the scheduler and read its handshake (and, at the start, to wait for a
#: first worker when it has none).
CONNECT_TIMEOUT_S = 10.0
#: Seconds a run waits, once the scheduler has no workers left, for one to join.
WORKER_WAIT_S = 60.0
#: Seconds between two checks of the cluster while tasks run.
POLL_S = 1.0
#: Environment variables that replace :data:`CONNECT_TIMEOUT_S` and :data:`WORKER_WAIT_S`.
CONNECT_ENV = "SYSID_DASK_CONNECT_TIMEOUT_S"
WORKER_WAIT_ENV = "SYSID_DASK_WORKER_WAIT_S"
#: A finished task's result (rows, a model: small) is fetched, and a sweep's data are sent
#: to the workers, within this many connect timeouts.
RESULT_WAITS = 10
#: A sweep ends (:class:`DataLost`) when its data were lost this many times in a row without
#: a past finishing in between (workers that keep leaving).
RESEND_LIMIT = 3
#: How long the result loop sleeps between looks at finished tasks.
_TICK_S = 0.02
#: Dashboard port hint for an address that accepts but does not answer.
_PORT_HINT = "the scheduler's port is usually 8786, the dashboard's 8787"


class SchedulerLost(ClusterError):
    """The connection to the scheduler was lost during a run (its tasks are gone with it)."""


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


def require_distributed() -> Any:
    """The ``distributed`` module, or one-line :class:`MissingDependencyError`."""
    try:
        import distributed
    except ImportError:
        raise MissingDependencyError(EXTRA_HINT) from None
    return distributed


def _seconds_from_env(name: str, default: float) -> float:
    text = os.environ.get(name, "").strip()
    if not text:
        return default
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0:
        raise ParameterError(f"{name}={text!r}: give a number of seconds > 0")
    return value


def connect_timeout_s() -> float:
    """:data:`CONNECT_TIMEOUT_S`, or the seconds in ``$SYSID_DASK_CONNECT_TIMEOUT_S``."""
    return _seconds_from_env(CONNECT_ENV, CONNECT_TIMEOUT_S)


def worker_wait_s() -> float:
    """:data:`WORKER_WAIT_S`, or the seconds in ``$SYSID_DASK_WORKER_WAIT_S``."""
    return _seconds_from_env(WORKER_WAIT_ENV, WORKER_WAIT_S)


# ----------------------------------------------------------------------------- connecting
def connect(address: str, *, timeout_s: float | None = None) -> Any:
    """A :class:`distributed.Client` of the scheduler at ``address`` (``tcp://HOST:PORT``).

    Raises a one-line :class:`ClusterError` within about ``timeout_s`` (default
    :func:`connect_timeout_s`) when nothing accepts the connection, when the peer does not
    answer the Dask handshake, or answers something else."""
    distributed = require_distributed()
    timeout = connect_timeout_s() if timeout_s is None else timeout_s
    where = f"--scheduler {address}"
    problem = probe(address, timeout_s=timeout)
    if problem is not None:
        raise ClusterError(f"{where}: {problem}")
    try:
        return _client_type(distributed)(address, timeout=timeout)
    except TimeoutError:  # it answered the probe, then stopped answering
        raise ClusterError(f"{where}: the scheduler does not answer (the client did not start "
                           f"within {timeout:g} s)") from None
    except Exception as exc:  # whatever the client met: one line, never a traceback
        raise ClusterError(f"{where}: cannot connect ({first_line(exc)})") from None


_CLIENT_TYPE: type | None = None


def _client_type(distributed: Any) -> type:
    """:class:`distributed.Client` with its start bounded by its ``timeout``.

    ``Client`` reads the scheduler's handshake without a limit (only connecting and its later
    requests are bounded), so a scheduler that stops answering between :func:`probe` and the
    client's start would hang it. Here the whole start is one wait of ``timeout`` seconds:
    when it ends, the start is cancelled on the client's loop, the client closed (its loop
    thread stopped) and :class:`TimeoutError` raised."""
    global _CLIENT_TYPE
    if _CLIENT_TYPE is not None and issubclass(_CLIENT_TYPE, distributed.Client):
        return _CLIENT_TYPE

    class BoundedClient(distributed.Client):
        async def _start(self, timeout: Any = None, **kwargs: Any) -> Any:
            limit = timeout if isinstance(timeout, (int, float)) else None
            return await asyncio.wait_for(super()._start(timeout=timeout, **kwargs), limit)

        def start(self, **kwargs: Any) -> None:
            try:
                super().start(**kwargs)
            except BaseException:
                with contextlib.suppress(Exception):  # bounded; stops its loop thread
                    self.close(timeout=kwargs.get("timeout") or CONNECT_TIMEOUT_S)
                raise

    BoundedClient.__qualname__ = "BoundedClient"
    _CLIENT_TYPE = BoundedClient
    return BoundedClient


def probe(address: str, *, timeout_s: float) -> str | None:
    """None when a Dask scheduler (or worker) answers at ``address`` within ``timeout_s``,
    else what is wrong, as the end of a sentence (``cannot connect (...)``, ``does not speak
    the Dask protocol (...)``).

    Connects as ``distributed`` does (retrying a refused connection until the time is up),
    then sends its handshake and reads the peer's, which ``distributed.Client`` waits for
    without a limit. Runs on an event loop of its own in a helper thread, so it works
    whatever loop the caller runs."""
    require_distributed()
    from distributed.comm import parse_address
    from distributed.comm.registry import get_backend
    from distributed.security import Security

    try:
        scheme, loc = parse_address(address)
        connector = get_backend(scheme).get_connector()
        args = Security().get_connection_args("client")
    except Exception as exc:  # a malformed address or an unknown scheme
        return f"cannot connect ({first_line(exc)})"
    if scheme == "inproc":  # same process: nothing can hang on the wire
        return None

    def run() -> str | None:
        loop = asyncio.new_event_loop()
        try:
            return loop.run_until_complete(_handshake(connector, loc, args, timeout_s))
        finally:
            loop.close()

    pool = concurrent.futures.ThreadPoolExecutor(max_workers=1,
                                                 thread_name_prefix="sysid-dask-probe")
    try:
        return pool.submit(run).result()
    finally:
        pool.shutdown(wait=False)


async def _handshake(connector: Any, loc: str, args: dict[str, Any],
                     timeout_s: float) -> str | None:
    from distributed.comm.core import FatalCommClosedError

    loop = asyncio.get_running_loop()
    deadline = loop.time() + timeout_s
    last: BaseException | None = None
    backoff = 0.01
    while True:
        left = deadline - loop.time()
        if left <= 0:
            return f"cannot connect ({_reason(last)}; tried for {timeout_s:g} s)"
        try:
            comm = await asyncio.wait_for(connector.connect(loc, deserialize=True, **args), left)
            break
        except (FatalCommClosedError, ValueError) as exc:  # a TLS certificate that does not
            return f"cannot connect ({first_line(exc)})"  # match, no port in the address
        except (TimeoutError, OSError) as exc:  # refused, unresolvable: retry
            last = exc
            await asyncio.sleep(min(backoff, max(deadline - loop.time(), 0.0)))
            backoff = min(2 * backoff, 1.0)

    async def exchange() -> Any:
        await comm.write(comm.handshake_info())
        return await comm.read()

    try:
        # at least a second for the answer, whatever the retries took
        answer = await asyncio.wait_for(exchange(), max(deadline - loop.time(),
                                                        min(timeout_s, 1.0)))
    except TimeoutError:
        return (f"cannot connect (the connection is accepted but nothing answers within "
                f"{timeout_s:g} s: is it a Dask scheduler? {_PORT_HINT})")
    except Exception as exc:  # garbage read as a frame length, undecodable bytes, a close
        from distributed.comm import CommClosedError

        log.debug("no Dask handshake from %s", loc, exc_info=exc)
        how = ("it closed the connection without a Dask handshake"
               if isinstance(exc, CommClosedError) else "its answer is no Dask handshake")
        return f"does not speak the Dask protocol ({how}; {_PORT_HINT})"
    finally:
        comm.abort()
    if not isinstance(answer, dict):
        return f"does not speak the Dask protocol (its answer is no Dask handshake; {_PORT_HINT})"
    return None


def _reason(exc: BaseException | None) -> str:
    """The operating system's words for a failed connection (``Connection refused``)."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        real = getattr(exc, "real_error", None)
        for e in (real, exc):
            if isinstance(e, OSError) and e.strerror:
                return str(e.strerror)
        if isinstance(exc, TimeoutError):
            return "timed out"
        exc = exc.__cause__ or exc.__context__
    return "no answer"


def dashboard_link(client: Any, *, label: str | None = None) -> str | None:
    """The cluster's dashboard address, or None when it has none. Asks the scheduler within
    :func:`connect_timeout_s` (``Client.dashboard_link`` and ``scheduler_info()`` wait without
    a limit): :class:`SchedulerLost` when it does not answer in that time, named ``label``
    (default: the :func:`watching` label, else ``--scheduler ADDRESS`` as :func:`connect`)."""
    timeout = connect_timeout_s()
    try:
        info = client.sync(client.scheduler.identity, n_workers=0, callback_timeout=timeout)
        port = info.get("services", {}).get("dashboard")
        if port is None:
            return None
        from distributed.comm import get_address_host
        from distributed.utils import format_dashboard_link

        host = get_address_host(client.scheduler.address)
        return str(format_dashboard_link(f"[{host}]" if ":" in host else host, port))
    except TimeoutError:
        label = label or _watch().label or f"--scheduler {_address(client)}"
        raise _lost(client, label, waited_s=timeout) from None
    except Exception:  # a missing dashboard is no error (a lost scheduler is seen next)
        return None


@contextlib.contextmanager
def quiet_dask_log() -> Iterator[None]:
    """Keep ``distributed``'s own log (its tracebacks of a lost scheduler, retries) off the
    terminal while the command reports the faults in one line; ``-v`` (INFO on the root
    logger) shows it."""
    if logging.getLogger().isEnabledFor(logging.INFO):
        yield
        return
    saved = {}
    for name in ("distributed", "tornado", "asyncio"):
        logger = logging.getLogger(name)
        saved[name] = (logger.handlers[:], logger.propagate)
        logger.handlers[:] = [logging.NullHandler()]
        logger.propagate = False
    try:
        yield
    finally:
        for name, (handlers, propagate) in saved.items():
            logger = logging.getLogger(name)
            logger.handlers[:] = handlers
            logger.propagate = propagate


# ------------------------------------------------------------------------------- watching
@dataclass(frozen=True)
class Watch:
    """How a run on the cluster reports and bounds faults (:func:`watching`)."""

    #: Names the cluster in messages (default: ``Dask scheduler ADDRESS``).
    label: str | None = None
    #: Seconds without a worker before the run ends (None: :func:`worker_wait_s`).
    worker_wait_s: float | None = None
    #: Seconds between two checks of the cluster.
    poll_s: float = POLL_S
    #: Where warnings go (None: this module's logger).
    notify: Callable[[str], None] | None = None


_WATCH: ContextVar[Watch | None] = ContextVar("sysid_cluster_watch", default=None)


def _watch() -> Watch:
    return _WATCH.get() or Watch()


@contextlib.contextmanager
def watching(*, label: str | None = None, worker_wait_s: float | None = None,
             poll_s: float = POLL_S,
             notify: Callable[[str], None] | None = None) -> Iterator[Watch]:
    """Within the block, runs on a cluster (:func:`completed`) name it ``label``, end after
    ``worker_wait_s`` without workers, check it every ``poll_s`` and warn through ``notify``."""
    watch = Watch(label=label, worker_wait_s=worker_wait_s, poll_s=poll_s, notify=notify)
    token = _WATCH.set(watch)
    try:
        yield watch
    finally:
        _WATCH.reset(token)


def _address(client: Any) -> str:
    try:
        return str(client.scheduler.address)
    except Exception:  # a client without a scheduler (closed)
        return "ADDRESS"


def _label(client: Any, watch: Watch) -> str:
    return watch.label or f"Dask scheduler {_address(client)}"


def _no_worker_hint(client: Any) -> str:
    return f"start one with `dask worker {_address(client)}`"


def _lost(client: Any, label: str, *, waited_s: float | None = None) -> SchedulerLost:
    if waited_s is not None:
        return SchedulerLost(f"{label}: the scheduler does not answer (waited {waited_s:g} s)")
    return SchedulerLost(f"{label}: lost the connection to the scheduler")


def worker_count(client: Any, *, label: str | None = None) -> int:
    """How many workers the scheduler has now (one request, answered within
    :func:`connect_timeout_s`); :class:`SchedulerLost` when the client has lost the scheduler
    or it does not answer (a hung scheduler keeps the connection open)."""
    label = label or _label(client, _watch())
    if client.status != "running":
        raise _lost(client, label)
    timeout = connect_timeout_s()
    try:
        return len(client.sync(client.scheduler.ncores, callback_timeout=timeout))
    except TimeoutError:
        raise _lost(client, label, waited_s=timeout) from None
    except Exception:  # unreachable (refused, reset) or the client closing under us
        raise _lost(client, label) from None


def wait_for_workers(client: Any, *, timeout_s: float, label: str | None = None) -> int:
    """Wait up to ``timeout_s`` for the scheduler to have a worker; their number, or a
    one-line :class:`ClusterError` naming ``dask worker ADDRESS``."""
    label = label or _label(client, _watch())
    deadline = time.monotonic() + timeout_s
    while True:
        n = worker_count(client, label=label)
        if n or time.monotonic() >= deadline:
            break
        time.sleep(min(0.2, max(deadline - time.monotonic(), 0.0)))
    if not n:
        raise ClusterError(f"{label}: the scheduler has no workers (waited {timeout_s:g} s); "
                           f"{_no_worker_hint(client)}")
    return n


class WorkerWatch:
    """The scheduler's workers during a run: :meth:`check` asks for their number (a lost
    scheduler is :class:`SchedulerLost`), warns when the last has left and when one is back,
    and ends the run (:class:`ClusterError`) once there has been none for the worker wait.
    One per run, so the wait goes on across a sweep's resends (:func:`run_pasts`)."""

    def __init__(self, client: Any, watch: Watch | None = None) -> None:
        watch = watch or _watch()
        self.client, self.label, self.poll_s = client, _label(client, watch), watch.poll_s
        self.wait_s = worker_wait_s() if watch.worker_wait_s is None else watch.worker_wait_s
        self.say = watch.notify or log.warning
        self.empty_since: float | None = None

    def check(self) -> int:
        n = worker_count(self.client, label=self.label)
        now = time.monotonic()
        if n and self.empty_since is not None:
            self.say(f"{self.label}: {n} worker(s) again")
            self.empty_since = None
        elif not n and self.empty_since is None:
            self.empty_since = now
            self.say(f"{self.label}: the scheduler has no workers; waiting up to "
                     f"{self.wait_s:g} s for one ({_no_worker_hint(self.client)})")
        elif not n and self.empty_since is not None and now - self.empty_since >= self.wait_s:
            raise ClusterError(f"{self.label}: the scheduler had no workers for "
                               f"{self.wait_s:g} s; {_no_worker_hint(self.client)}")
        return n

    def until_one(self) -> int:
        """Wait for a worker (bounded by the worker wait); their number."""
        while True:
            n = self.check()
            if n:
                return n
            time.sleep(self.poll_s)


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
