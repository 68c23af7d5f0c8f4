"""Fixtures of the Dask fault tests: listeners, a flight, clusters in this process and in
another one (:mod:`tests.sysid.cluster_fakes`)."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sysid.batch
from sysid.batch import run_batch
from sysid.data import IOData
from sysid.methods import get_method
from tests.sysid import cluster_fakes
from tests.sysid.cluster_faults.support import (
    ROOT,
    Listener,
    env,
)
from tests.sysid.flights import known_system, write_flight

distributed = pytest.importorskip("distributed")


@pytest.fixture
def silent() -> Iterator[Listener]:
    listener = Listener()
    yield listener
    listener.close()


@pytest.fixture
def garbage() -> Iterator[Listener]:
    listener = Listener(b"HTTP/1.1 400 Bad Request\r\nContent-Length: 0\r\n\r\n" * 4)
    yield listener
    listener.close()


@pytest.fixture(scope="module")
def session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("faults")
    return write_flight(d / "s0.h5", system=known_system(), seed=50, n=1200).path


@pytest.fixture
def fake_batch(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> Iterator[Any]:
    """``run(names, client, **kw)``: a batch of groups named after their delays
    (:mod:`tests.sysid.cluster_fakes`) on ``client``; blocked tasks are released at the end."""
    monkeypatch.setattr(sysid.batch, "identify_group", cluster_fakes.fake_identify)
    rng = np.random.default_rng(1)

    def load(paths: list[Path]) -> list[list[Any]]:  # the fake reads only the name
        return [[IOData(u=rng.normal(size=(200, 1)), y=rng.normal(size=(200, 1)), dt=0.02,
                        source=str(paths[0]))]]

    def run(names: list[str], client: Any, **kw: Any) -> list[Any]:
        groups = {n.partition("_")[0]: [tmp_path / f"{n}.h5"] for n in names}
        return run_batch(groups, out_dir=tmp_path / "out", load=load,
                         method=get_method("iem"), options=get_method("iem").options(),
                         grid={}, client=client, **kw)

    cluster_fakes.GATE.clear()
    yield run
    cluster_fakes.GATE.set()


@pytest.fixture
def threads() -> Iterator[tuple[Any, Any]]:
    """A scheduler with one worker of two threads, in this process; a client of it."""
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                       protocol="tcp://", host="127.0.0.1",
                                       dashboard_address="127.0.0.1:0")
    client = distributed.Client(cluster.scheduler_address, timeout=10)
    yield cluster, client
    cluster_fakes.GATE.set()
    client.close(timeout=10)
    cluster.close(timeout=10)



@pytest.fixture
def killable() -> Iterator[tuple[subprocess.Popen[str], str]]:
    """A one-process cluster (:func:`tests.sysid.cluster_fakes.serve`) and its address."""
    proc = subprocess.Popen([sys.executable, "-m", "tests.sysid.cluster_fakes"], cwd=ROOT,
                            env=env(), stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    try:
        address = proc.stdout.readline().strip()
        assert address.startswith("tcp://127.0.0.1:"), address
        yield proc, address
    finally:
        proc.kill()
        proc.wait(timeout=30)



@pytest.fixture
def four() -> Iterator[tuple[Any, Any]]:
    """A scheduler with four one-thread workers in this process (Dask's default
    allowed-failures, 3, lets a task lose four); a client of it."""
    cluster = distributed.LocalCluster(n_workers=4, threads_per_worker=1, processes=False,
                                       protocol="tcp://", host="127.0.0.1",
                                       dashboard_address="127.0.0.1:0")
    client = distributed.Client(cluster.scheduler_address, timeout=10)
    cluster_fakes.LOSE.clear()
    yield cluster, client
    cluster_fakes.LOSE.set()
    cluster_fakes.GATE.set()
    client.close(timeout=10)
    cluster.close(timeout=10)
