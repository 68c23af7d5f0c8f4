"""Watching the cluster during a command: how a run names it in its messages, checks it and
warns (:class:`Watch`, set for a block by :func:`watching`), and the requests that wait for
the scheduler's answer. Each fault is one :class:`~sysid.errors.ClusterError` line:

- every request that waits for the scheduler's answer (:func:`dashboard_link`,
  :func:`worker_count`) gets the connect timeout; a scheduler that does not answer in that
  time is :class:`SchedulerLost` (and so is a lost connection, for :func:`worker_count`);
- a scheduler without workers is reported through the :func:`watching` ``notify`` and ends
  the run when no worker has joined within the worker wait (:class:`WorkerWatch`, one per
  run); at the start, :func:`wait_for_workers` waits for a first one.
"""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import Callable, Iterator
from contextvars import ContextVar
from dataclasses import dataclass
from typing import Any

from sysid.cluster.connection import connect_timeout_s, worker_wait_s
from sysid.errors import ClusterError

__all__ = ["POLL_S", "SchedulerLost", "Watch", "WorkerWatch", "dashboard_link",
           "wait_for_workers", "watching", "worker_count"]

log = logging.getLogger("sysid.cluster")  # the package's one logger

#: Seconds between two checks of the cluster while tasks run.
POLL_S = 1.0


class SchedulerLost(ClusterError):
    """The connection to the scheduler was lost during a run (its tasks are gone with it)."""


@dataclass(frozen=True)
class Watch:
    """How a run on the cluster reports and bounds faults (:func:`watching`)."""

    #: Names the cluster in messages (default: ``Dask scheduler ADDRESS``).
    label: str | None = None
    #: Seconds without a worker before the run ends (None: :func:`worker_wait_s`).
    worker_wait_s: float | None = None
    #: Seconds between two checks of the cluster.
    poll_s: float = POLL_S
    #: Where warnings go (None: the ``sysid.cluster`` logger).
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
