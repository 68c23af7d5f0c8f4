"""Sweeps on a Dask cluster: the same rows as locally, the grid scattered once per worker."""

from __future__ import annotations

import builtins
import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sysid.cluster import EXTRA_HINT, require_distributed
from sysid.errors import MissingDependencyError
from sysid.grid import HorizonGrid
from sysid.sweep import sweep
from tests.sysid.systems import closed_loop, pbsid_example1

distributed = pytest.importorskip("distributed")

GRID = {"pasts": [4, 8], "futures": [3, 6], "orders": [3, 4]}


@pytest.fixture(scope="module")
def client() -> Iterator[Any]:
    """A 2-process LocalCluster on 127.0.0.1, always shut down. Its HTTP service (which
    serves the dashboard when bokeh is installed, it is not here) takes a free port."""
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       host="127.0.0.1", dashboard_address="127.0.0.1:0",
                                       death_timeout=60)
    c = distributed.Client(cluster, timeout=60)
    try:
        c.wait_for_workers(2, timeout=120)
        yield c
    finally:
        c.close(timeout=60)
        cluster.close(timeout=60)


@pytest.fixture(scope="module")
def data() -> tuple[Any, Any]:
    rng = np.random.default_rng(3)
    system = pbsid_example1()
    return (closed_loop(system, n_samples=1200, rng=rng).data,
            closed_loop(system, n_samples=600, rng=rng).data)


class _Spy:
    """A client that records what it is asked to send."""

    def __init__(self, inner: Any) -> None:
        self.inner, self.scatters, self.submits = inner, [], []

    def scatter(self, data: Any, **kwargs: Any) -> Any:
        self.scatters.append((data, kwargs))
        return self.inner.scatter(data, **kwargs)

    def submit(self, *args: Any, **kwargs: Any) -> Any:
        self.submits.append((args, kwargs))
        return self.inner.submit(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)


def test_cluster_sweep_equals_local_run_and_scatters_once(client: Any, data: Any) -> None:
    ident, val = data
    local = sweep(ident, **GRID, validation=val, horizon=1)
    spy = _Spy(client)
    done: list[int] = []
    remote = sweep(ident, **GRID, validation=val, horizon=1, client=spy,
                   progress=lambda n, _total: done.append(n))
    assert [(r.past, r.future, r.order) for r in remote.rows] == \
        [(r.past, r.future, r.order) for r in local.rows]
    for a, b in zip(local.rows, remote.rows, strict=True):
        assert a.error == b.error
        np.testing.assert_array_equal(a.poles, b.poles)
        np.testing.assert_array_equal(a.fit, b.fit)
    assert remote.best().order == local.best().order == 4
    # the grid went out once, to every worker; each task carries only its past
    assert len(spy.scatters) == 1 and spy.scatters[0][1]["broadcast"] is True
    assert isinstance(spy.scatters[0][0][0]["grid"], HorizonGrid)
    assert len(spy.submits) == len(GRID["pasts"])
    for args, kwargs in spy.submits:
        sent = [*args, *kwargs.values()]
        assert not any(isinstance(v, HorizonGrid | np.ndarray | tuple) for v in sent)
    assert sorted(done)[-1] == len(local.rows)


def test_missing_distributed_names_the_extra(monkeypatch: pytest.MonkeyPatch) -> None:
    real = builtins.__import__

    def fake(name: str, *args: Any, **kwargs: Any) -> Any:
        if name == "distributed" or name.startswith("distributed."):
            raise ImportError("No module named 'distributed'")
        return real(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", fake)
    with pytest.raises(MissingDependencyError) as err:
        require_distributed()
    assert str(err.value) == EXTRA_HINT and "cf-sysid[dask]" in str(err.value)


@pytest.fixture(scope="module")
def sessions(tmp_path_factory: pytest.TempPathFactory) -> list[Any]:
    from tests.sysid.flights import known_system, write_flight

    d = tmp_path_factory.mktemp("dask")
    system = known_system()
    return [write_flight(d / f"s{i}.h5", system=system, seed=50 + i, n=1200).path
            for i in range(3)]


def _cli(*args: object) -> Any:
    from click.testing import CliRunner

    from sysid.cli import main

    return CliRunner().invoke(main, [str(a) for a in args])


def test_cli_sweep_on_the_scheduler_equals_the_local_sweep(client: Any, sessions: Any) -> None:
    grid = ["--pasts", "10,20", "--futures", "5,10", "--orders", "3,4", "--json"]
    local = _cli("sweep", sessions[0], *grid)
    remote = _cli("sweep", sessions[0], *grid, "--scheduler", client.scheduler.address)
    assert local.exit_code == 0 and remote.exit_code == 0, remote.output
    a, b = json.loads(local.stdout), json.loads(remote.stdout)
    for ra, rb in zip(a["top"], b["top"], strict=True):
        ra.pop("seconds"), rb.pop("seconds")
        assert ra == rb
    assert a["best"]["poles"] == b["best"]["poles"]
    assert (f"dask: {client.scheduler.address}, 2 worker(s), dashboard {client.dashboard_link}"
            in remote.stderr)


def test_cli_batch_on_the_scheduler_equals_the_local_batch(client: Any, sessions: Any,
                                                           tmp_path: Any) -> None:
    fixed = ["--order", "4", "--past", "20", "--future", "10"]
    local = _cli("batch", *sessions, "--out", tmp_path / "local", *fixed)
    remote = _cli("batch", *sessions, "--out", tmp_path / "dask", *fixed,
                  "--scheduler", client.scheduler.address)
    assert local.exit_code == 0 and remote.exit_code == 0, remote.output
    rows = [json.loads((tmp_path / d / "summary.json").read_text()) for d in ("local", "dask")]
    # the same rows in the same (input) order; only the model's folder and the time differ
    assert [r["group"] for r in rows[0]] == [r["group"] for r in rows[1]] == ["s0", "s1", "s2"]
    for a, b in zip(*rows, strict=True):
        assert a["error"] is None and a["seconds"] > 0 and b["seconds"] > 0
        assert Path(a.pop("model")).name == Path(b.pop("model")).name
        a.pop("seconds"), b.pop("seconds")
        assert a == b
    assert "batch: 3/3 (100 %)" in remote.stderr


def test_cli_scheduler_without_the_extra_is_one_line(monkeypatch: pytest.MonkeyPatch,
                                                     sessions: Any) -> None:
    import sysid.cluster.connection

    def missing() -> Any:
        raise MissingDependencyError(EXTRA_HINT)

    # where connect() looks it up (the package's name is the same object, read by callers only)
    monkeypatch.setattr(sysid.cluster.connection, "require_distributed", missing)
    res = _cli("sweep", sessions[0], "--scheduler", "tcp://127.0.0.1:8786")
    assert res.exit_code == 2
    assert res.stderr.strip().splitlines() == [f"error: {EXTRA_HINT}"]


def test_dashboard_link_is_none_without_a_dashboard() -> None:
    """A scheduler whose identity lists no dashboard service: no link (the client's own
    ``dashboard_link`` would invent one)."""
    from types import SimpleNamespace

    from sysid.cluster import dashboard_link

    class NoDashboard:
        dashboard_link = "http://unused"
        scheduler = SimpleNamespace(address="tcp://127.0.0.1:8786",
                                    identity=lambda **_: {"services": {}, "workers": {}})

        def sync(self, fn: Any, **kwargs: Any) -> Any:
            kwargs.pop("callback_timeout")
            return fn(**kwargs)

    assert dashboard_link(NoDashboard()) is None


def test_cli_bad_scheduler_address_is_one_line(sessions: Any) -> None:
    res = _cli("sweep", sessions[0], "--scheduler", "nonsense", "--orders", "4")
    assert res.exit_code == 2
    assert res.stderr.strip().splitlines() == [
        "error: --scheduler nonsense: cannot connect (missing port number in address "
        "'nonsense')"]
