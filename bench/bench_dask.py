"""Local worker processes vs a 2-worker Dask LocalCluster: ``python -m bench dask``.

1. The thesis-sized 756-pair sweep of ``bench_sweep`` (IEM, n=8 m=4 l=6, N=15000, order 8,
   2 s windowed simulation on a second record): ``sweep(workers=2)`` vs ``sweep(client=...)``
   on ``LocalCluster(n_workers=2, threads_per_worker=1)``. The rows must be identical.
2. A 50-session batch: sessions written with the session writer from a known system (as
   ``tests/sysid_io/flights.py`` does), one model per session, past 20, future 10, orders
   2..8 chosen by validation: locally (groups one after another) vs one task per group on the
   cluster.

Printed: wall times, ratios, what is scattered once per worker (bytes) and what each task
carries, the cluster's start-up time (not in the ratios) and the load average: on a shared
2-core machine the ratio says how much the Dask path costs, not how a real cluster scales.
Returns 0 when the cluster's rows equal the local ones.
"""

from __future__ import annotations

import importlib
import os
import pickle
import tempfile
import time
from pathlib import Path

import numpy as np

from sysid.batch import group_sessions, run_batch
from sysid.grid import build_grid
from sysid.methods import get_method
from sysid.session_io import load_sessions
from sysid.sweep import sweep
from tests.sysid.flights import known_system, write_flight
from tests.sysid.systems import open_loop, random_stable_system

__all__ = ["main"]

PASTS = range(25, 61)
FUTURES = range(5, 26)
ORDER = 8
WINDOW_S = 2.0
N_SESSIONS = 50
BATCH_GRID = {"pasts": [20], "futures": [10], "orders": list(range(2, 9))}


def _rows(result: object) -> list[tuple]:
    return [(r.past, r.future, r.order, r.error, r.fit.tobytes(), r.poles.tobytes())
            for r in result.rows]


def _bench_sweep(client: object) -> bool:
    rng = np.random.default_rng(2024)
    system = random_stable_system(n_states=8, n_inputs=4, n_outputs=6, rng=rng)
    data = open_loop(system, n_samples=15000, rng=rng, noise_std=0.2).data
    val = open_loop(system, n_samples=15000, rng=rng, noise_std=0.2).data
    kw = {"pasts": PASTS, "futures": FUTURES, "orders": [ORDER], "validation": val,
          "window": WINDOW_S}
    grid = build_grid(data, past_max=max(PASTS), future_max=max(FUTURES))
    scattered = len(pickle.dumps({"grid": grid, "validation": (val,)}))
    t0 = time.perf_counter()
    local = sweep(data, workers=2, **kw)
    t_local = time.perf_counter() - t0
    t0 = time.perf_counter()
    remote = sweep(data, client=client, **kw)
    t_dask = time.perf_counter() - t0
    same = _rows(local) == _rows(remote)
    print(f"  756-pair sweep: local 2 processes {t_local:6.1f} s, Dask 2 workers "
          f"{t_dask:6.1f} s, ratio local/dask {t_local / t_dask:4.2f}; rows identical: {same}")
    print(f"    scattered once per worker: {scattered / 1e6:.1f} MB (Gram "
          f"{grid.gram.nbytes / 1e6:.2f} MB + identification and validation records); "
          f"per task: one past and the method options ({len(PASTS)} tasks)")
    return same


def _bench_batch(client: object) -> bool:
    with tempfile.TemporaryDirectory(prefix="bench-dask-") as tmp:
        d = Path(tmp)
        system = known_system()
        t0 = time.perf_counter()
        paths = [write_flight(d / f"s{i:02d}.h5", system=system, seed=100 + i, n=1500).path
                 for i in range(N_SESSIONS)]
        print(f"  {N_SESSIONS} sessions written in {time.perf_counter() - t0:.1f} s "
              f"({sum(p.stat().st_size for p in paths) / 1e6:.1f} MB)")
        groups, _ = group_sessions(paths, by="session", read_meta=dict)
        meth = get_method("iem")

        def load(ps: list[Path]) -> list[list]:
            return load_sessions(list(ps), inputs=["motors"], outputs=["acc.z", "gyro"])

        out = {}
        for label, kw in (("local", {"workers": 1}), ("dask", {"client": client})):
            t0 = time.perf_counter()
            rows = run_batch(groups, out_dir=d / label, load=load, method=meth,
                             options=meth.options(), grid=BATCH_GRID, **kw)
            out[label] = (time.perf_counter() - t0, rows)
        (t_l, rows_l), (t_d, rows_d) = out["local"], out["dask"]
        key = {r.group: (r.order, r.fit, [complex(p) for p in r.poles]) for r in rows_l}
        same = key == {r.group: (r.order, r.fit, [complex(p) for p in r.poles]) for r in rows_d}
        n_fail = sum(r.error is not None for r in rows_d)
        print(f"  {N_SESSIONS}-session batch (orders 2..8 by validation): local (one group "
              f"after another) {t_l:6.1f} s, Dask 2 workers {t_d:6.1f} s, ratio "
              f"{t_l / t_d:4.2f}; {n_fail} failed; rows identical: {same}")
        return same


def main() -> int:
    """0 when the cluster's sweep and batch rows equal the local ones."""
    try:
        import distributed
    except ImportError:
        print("  skipped: pip install 'cf-sysid[dask]'")
        return 0
    if os.environ.get("BENCH_DASK_PROFILE", "1") == "0":  # the workers' sampling profiler
        import dask

        dask.config.set({"distributed.worker.profile.enabled": False})
    t0 = time.perf_counter()
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       host="127.0.0.1", dashboard_address="127.0.0.1:0")
    client = distributed.Client(cluster)
    try:
        client.wait_for_workers(2, timeout=120)
        t1 = time.perf_counter()
        client.run(importlib.import_module, "sysid.batch")  # imports, as the local pool's
        print(f"  workers import sysid in {time.perf_counter() - t1:.1f} s (not timed below)")
        print(f"  LocalCluster (2 worker processes, 1 thread each) up in "
              f"{time.perf_counter() - t0:.1f} s; load average {os.getloadavg()[0]:.1f} on "
              f"{os.cpu_count()} cores")
        ok = _bench_sweep(client)
        ok = _bench_batch(client) and ok
    finally:
        client.close()
        cluster.close()
    return 0 if ok else 1
