"""PBSID toolbox Example 1 over 100 Monte Carlo runs (5 seeds x 20): IEM against SIPPY on the
same data, paired, against the maximum-likelihood estimate, and PO-MOESP.

The experiment is the toolbox script's closed-loop one (``u = r - 0.25 y``, ``r ~ N(0, I)``,
innovations scaled by 0.7, N=4000, n=4, p=f=10; ``tests.sysid.systems.pbsid_example1_closed_loop``).
A 20-run mean of the worst-pole error moves by several 1e-4 from one seed to the next, so each
seed's mean is printed, and the paired difference IEM - PARSIM-K on identical data is the figure
that tells the methods apart. "ML" is the prediction-error estimate started at the *true*
system and iterated to convergence (``sysid.pem.pem_refine``, 60 iterations): the
maximum-likelihood estimate for Gaussian innovations, the efficiency reference no method beats
on average. Set ``BENCH_PBSID_NOISE`` to change the innovation scale (1.0 gives unit-variance
innovations, the setting in which SIPPY's MOESP shows about 0.03). Takes about 10 minutes.

Targets (issue 3): IEM's 20-run mean <= 0.005 on every seed, and IEM no worse than PARSIM-K
(paired mean difference <= 2 s.e.).
"""

from __future__ import annotations

import logging
import os

import numpy as np

import sysid
from bench.bench_sysid import _sippy_parsim_k
from sysid.pem import pem_refine
from tests.sysid.systems import (
    PBSID_CLOSED_LOOP_NOISE_STD,
    closed_loop,
    pbsid_example1,
    pole_error,
)

SEEDS, RUNS = range(5), 20
KW = {"order": 4, "past": 10, "future": 10}
BAR = 0.005


def _ml_poles(system: sysid.StateSpaceModel, data: sysid.IOData) -> np.ndarray:
    truth = (system.A, system.B, system.C, system.D, system.K, np.eye(system.n_outputs))
    (a, *_), _status = pem_refine(matrices=truth, flights=[(data.u, data.y)], feedthrough=False,
                                  max_iterations=60)
    return np.linalg.eigvals(a)


def _run_seed(seed: int, system: sysid.StateSpaceModel,
              noise: float) -> dict[str, list[float]] | None:
    res: dict[str, list[float]] = {"IEM": [], "ML": [], "PARSIM-K": [], "PO-MOESP": [],
                                   "SIPPY PARSIM-K": [], "SIPPY MOESP": []}
    rng = np.random.default_rng(seed)
    for _ in range(RUNS):
        d = closed_loop(system, n_samples=4000, rng=rng, gain=0.25, noise_std=noise).data
        for method in ("PARSIM-K", "MOESP"):
            sip = _sippy_parsim_k(d, method=method, **KW)
            if sip is None:
                return None
            res[f"SIPPY {method}"].append(pole_error(system.poles(), np.linalg.eigvals(sip.A)))
        res["IEM"].append(pole_error(system.poles(), sysid.iem(d, **KW).poles()))
        res["ML"].append(pole_error(system.poles(), _ml_poles(system, d)))
        res["PARSIM-K"].append(pole_error(
            system.poles(), sysid.parsim_k(d, feedthrough=False, **KW).poles()))
        res["PO-MOESP"].append(pole_error(
            system.poles(), sysid.po_moesp(d, feedthrough=False, **KW).poles()))
    return res


def main() -> int:
    logging.disable(logging.WARNING)
    system = pbsid_example1()
    noise = float(os.environ.get("BENCH_PBSID_NOISE", PBSID_CLOSED_LOOP_NOISE_STD))
    print(f"innovation scale {noise} (the toolbox script's closed loop: "
          f"{PBSID_CLOSED_LOOP_NOISE_STD})")
    res: dict[str, list[float]] = {}
    seed_means = []
    for seed in SEEDS:
        one = _run_seed(seed, system, noise)
        if one is None:
            print("SIPPY not installed: pip install -e '.[bench]'")
            return 1
        seed_means.append(np.mean(one["IEM"]))
        for k, v in one.items():
            res.setdefault(k, []).extend(v)
        print(f"seed {seed}, {RUNS} runs, mean: "
              + ", ".join(f"{k} {np.mean(v):.4f}" for k, v in one.items()), flush=True)
    n = len(res["IEM"])
    for k, v in res.items():
        a = np.asarray(v)
        print(f"  {k:<15} n={n} mean {a.mean():.4f} +- {a.std(ddof=1) / np.sqrt(n):.4f} (s.e.)"
              f"  median {np.median(a):.4f}  worst {a.max():.4f}")
    diff = np.asarray(res["IEM"]) - np.asarray(res["SIPPY PARSIM-K"])
    se = diff.std(ddof=1) / np.sqrt(n)
    print(f"paired IEM - PARSIM-K: {diff.mean():+.4f} +- {se:.4f} (s.e.); IEM better in "
          f"{np.mean(diff < 0):.0%} of runs; ratio of means "
          f"{np.mean(res['IEM']) / np.mean(res['SIPPY PARSIM-K']):.2f}")
    ours = np.asarray(res["PARSIM-K"]) - np.asarray(res["SIPPY PARSIM-K"])
    print(f"paired PARSIM-K (ours) - SIPPY's: {ours.mean():+.5f}, largest |difference| "
          f"{np.abs(ours).max():.5f}")
    print(f"ratio of means IEM / ML: {np.mean(res['IEM']) / np.mean(res['ML']):.2f}; ML's 20-run "
          f"means per seed: " + ", ".join(f"{np.mean(res['ML'][i:i + RUNS]):.4f}"
                                          for i in range(0, n, RUNS)))
    worst_seed = max(seed_means)
    ml_means = [np.mean(res["ML"][i:i + RUNS]) for i in range(0, n, RUNS)]
    print(f"IEM 20-run means {min(seed_means):.4f}-{worst_seed:.4f}: bar {BAR} met on "
          f"{sum(m <= BAR for m in seed_means)} of {len(seed_means)} seeds "
          f"(ML on {sum(m <= BAR for m in ml_means)} of {len(ml_means)})")
    return 0 if worst_seed <= BAR and diff.mean() <= 2 * se else 1
