"""Running sweeps and batches on an existing Dask distributed cluster (optional extra).

``pip install cf-sysid[dask]`` installs ``dask[distributed]``; without it, asking for a
cluster raises :class:`~sysid.errors.MissingDependencyError` with one line naming the extra.

**What is sent.** A sweep's data products (the grid's Gram matrix with its flights, and the
validation records) are scattered *once per worker* (``client.scatter(..., broadcast=True)``);
each task then carries only its past (an integer) and the small method/options objects, and
returns its rows. The workers run the same :func:`sysid.sweep._past_task` as the local worker
processes, on the same arrays, so the rows are the same. A batch sends each group's records
with that group's one task (they are needed by one worker only).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from typing import Any

from sysid.errors import MissingDependencyError

__all__ = ["EXTRA_HINT", "connect", "dashboard_link", "require_distributed", "run_pasts"]

log = logging.getLogger(__name__)

EXTRA_HINT = "dask.distributed is not installed; install the extra: pip install 'cf-sysid[dask]'"


def require_distributed() -> Any:
    """The ``distributed`` module, or one-line :class:`MissingDependencyError`."""
    try:
        import distributed
    except ImportError:
        raise MissingDependencyError(EXTRA_HINT) from None
    return distributed


def connect(address: str, *, timeout_s: float = 10.0) -> Any:
    """A :class:`distributed.Client` of the scheduler at ``address`` (``tcp://HOST:PORT``)."""
    distributed = require_distributed()
    from sysid.errors import ParameterError

    try:
        return distributed.Client(address, timeout=timeout_s)
    except (OSError, TimeoutError, ValueError) as exc:
        first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ParameterError(f"--scheduler {address}: cannot connect ({first})") from None


def dashboard_link(client: Any) -> str | None:
    """The cluster's dashboard address, or None when it has none."""
    try:
        info = client.scheduler_info()
        if "dashboard" not in info.get("services", {}):
            return None
        return str(client.dashboard_link)
    except Exception:  # a missing dashboard is no error
        return None


def run_pasts(client: Any, *, task: Callable[..., Any], shared: dict[str, Any],
              common: dict[str, Any], pasts: Iterable[int],
              finished: Callable[[int, Any], None]) -> None:
    """Run ``task(past=p, **shared, **common)`` for every past on the cluster.

    ``shared`` (the large data products) is scattered once to every worker; ``finished(p,
    result)`` is called here as each past ends. On any exception here (Ctrl-C included) the
    pending tasks are cancelled before it propagates."""
    distributed = require_distributed()
    [handle] = client.scatter([shared], broadcast=True, hash=False)
    futures = {client.submit(_with_shared, task, handle, past=p, pure=False, **common): p
               for p in pasts}
    try:
        for fut in distributed.as_completed(futures):
            finished(futures[fut], fut.result())
    except BaseException:
        client.cancel(list(futures))
        raise
    finally:
        client.cancel([handle])


def _with_shared(task: Callable[..., Any], shared: dict[str, Any], **kwargs: Any) -> Any:
    return task(**shared, **kwargs)
