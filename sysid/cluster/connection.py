"""Reaching a Dask scheduler: the optional extra, the two waits, the bounded connection.

``distributed`` is imported on use (:func:`require_distributed`): without it, asking for a
cluster is one :class:`~sysid.errors.MissingDependencyError` line naming the extra. Every
wait while connecting is bounded, and each fault is one :class:`~sysid.errors.ClusterError`
line:

- :func:`connect` first opens a connection itself and reads the scheduler's Dask handshake,
  each step within the connect timeout (``distributed.Client`` waits for that answer without
  a limit): an address that accepts but never answers, or answers something other than Dask
  (an HTTP server, the dashboard's port), is refused within that time. The client's own
  start (its connection, handshake and registration) is bounded by the connect timeout too,
  so a scheduler that stops answering after that check is refused as well.

The two waits default to :data:`CONNECT_TIMEOUT_S` and :data:`WORKER_WAIT_S`; the
environment variables :data:`CONNECT_ENV` and :data:`WORKER_WAIT_ENV` (seconds) replace them
(:func:`connect_timeout_s`, :func:`worker_wait_s`). :func:`quiet_dask_log` keeps Dask's own
log off the terminal while a command reports the faults in one line.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import math
import os
from collections.abc import Iterator
from typing import Any

from sysid.errors import ClusterError, MissingDependencyError, ParameterError, first_line

__all__ = ["CONNECT_ENV", "CONNECT_TIMEOUT_S", "EXTRA_HINT", "WORKER_WAIT_ENV", "WORKER_WAIT_S",
           "connect", "connect_timeout_s", "probe", "quiet_dask_log", "require_distributed",
           "worker_wait_s"]

log = logging.getLogger("sysid.cluster")  # the package's one logger

EXTRA_HINT = "dask.distributed is not installed; install the extra: pip install 'cf-sysid[dask]'"

#: Seconds to reach the scheduler and read its handshake (and, at the start, to wait for a
#: first worker when it has none).
CONNECT_TIMEOUT_S = 10.0
#: Seconds a run waits, once the scheduler has no workers left, for one to join.
WORKER_WAIT_S = 60.0
#: Environment variables that replace :data:`CONNECT_TIMEOUT_S` and :data:`WORKER_WAIT_S`.
CONNECT_ENV = "SYSID_DASK_CONNECT_TIMEOUT_S"
WORKER_WAIT_ENV = "SYSID_DASK_WORKER_WAIT_S"
#: Dashboard port hint for an address that accepts but does not answer.
_PORT_HINT = "the scheduler's port is usually 8786, the dashboard's 8787"


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
