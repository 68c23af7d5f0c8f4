"""Reaching the scheduler: an address that accepts but never answers, one that answers
something else, a refused port, a scheduler without workers, and one that stops answering
(``SIGSTOP``) before the client has started, during a sweep's scatter or once connected: one
line each, within the connect timeout (shortened here, ``SYSID_DASK_*``; the deadlines
asserted are generous, so the machine's load does not matter)."""

from __future__ import annotations

import asyncio
import socket
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import pytest

import sysid.cluster
import sysid.cluster.connection
from sysid.cluster import (
    CONNECT_ENV,
    WORKER_WAIT_ENV,
    SchedulerLost,
    connect,
    dashboard_link,
    scatter,
    watching,
)
from sysid.errors import ClusterError, ParameterError
from tests.sysid.cluster_faults.support import (
    CONNECT_S,
    DEADLINE_S,
    Listener,
    clean,
    cli,
    run_sysid,
    stop,
    sweep_args,
)

distributed = pytest.importorskip("distributed")


def test_silent_address_is_one_line_within_the_connect_timeout(session: Path,
                                                                silent: Listener) -> None:
    proc, took = run_sysid(*sweep_args(session, silent.address))
    assert proc.returncode == 2, proc.stderr
    assert clean(proc.stderr) == [
        f"error: --scheduler {silent.address}: cannot connect (the connection is accepted but "
        f"nothing answers within {CONNECT_S:g} s: is it a Dask scheduler? the scheduler's "
        "port is usually 8786, the dashboard's 8787)"]
    assert took < DEADLINE_S
    assert silent.conns  # it did connect: the handshake is what never came


def test_non_dask_service_is_one_line(session: Path, garbage: Listener) -> None:
    proc, took = run_sysid(*sweep_args(session, garbage.address))
    assert proc.returncode == 2, proc.stderr
    [line] = clean(proc.stderr)
    assert line.startswith(f"error: --scheduler {garbage.address}: does not speak the Dask "
                           "protocol (")
    assert "EiB" not in line and took < DEADLINE_S


def test_connect_bounds_the_handshake_in_process(silent: Listener, garbage: Listener) -> None:
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
        proc, took = run_sysid(*sweep_args(session, address))
    assert proc.returncode == 2, proc.stderr
    lines = clean(proc.stderr)
    assert lines[0].startswith(f"dask: {address}, 0 worker(s)")
    assert lines[0].endswith(f"; waiting up to {CONNECT_S:g} s for one")
    assert lines[1:] == [f"error: --scheduler {address}: the scheduler has no workers (waited "
                         f"{CONNECT_S:g} s); start one with `dask worker {address}`"]
    assert took < DEADLINE_S



def test_scheduler_that_stops_answering_before_the_client_starts_is_one_line(
        killable: tuple[subprocess.Popen[str], str], session: Path,
        monkeypatch: pytest.MonkeyPatch) -> None:
    """It answers the handshake check, then nothing: ``distributed.Client`` would wait for its
    own handshake forever; the command ends within the connect timeout."""
    server, address = killable
    real = sysid.cluster.connection.probe

    def probe_then_stop(*args: Any, **kwargs: Any) -> str | None:
        problem = real(*args, **kwargs)
        stop(server)
        return problem

    monkeypatch.setattr(sysid.cluster.connection, "probe", probe_then_stop)  # connect()'s call
    monkeypatch.setenv(CONNECT_ENV, str(CONNECT_S))
    before = set(threading.enumerate())
    res, took = cli(*sweep_args(session, address))
    assert res.exit_code == 2, res.output
    assert clean(res.stderr) == [f"error: --scheduler {address}: the scheduler does not "
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
        stop(server)
        return real(self, *args, **kwargs)

    monkeypatch.setattr(distributed.Client, "scatter", stop_then_scatter)
    monkeypatch.setenv(CONNECT_ENV, str(CONNECT_S))
    res, took = cli(*sweep_args(session, address))
    assert res.exit_code == 2, res.output
    lines = clean(res.stderr)
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
        stop(server)
        return client

    monkeypatch.setattr(sysid.cluster, "connect", connect_then_stop)  # the CLI imports it here
    monkeypatch.setenv(CONNECT_ENV, str(CONNECT_S))
    res, took = cli(*sweep_args(session, address))
    assert res.exit_code == 2, res.output
    assert clean(res.stderr) == [f"error: --scheduler {address}: the scheduler does not "
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


