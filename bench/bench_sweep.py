"""The thesis-sized horizon sweep with one factorization: ``python -m bench sweep``.

756 pairs (pasts 25..60, futures 5..25, order 8) of IEM on the thesis-sized case of
``bench_sysid`` (random stable system n=8, m=4, l=6, N=15000), each model scored by simulation
over 2 s windows on a second record of the same size. Printed: the sweep's wall time with
``BENCH_SWEEP_WORKERS`` workers (default 2), and the same pairs built independently
(``sysid.iem`` on each pair's own data, as the sweep did before) on an evenly spread subset of
``BENCH_SWEEP_SUBSET`` pairs (default 24), timed in the same run and extrapolated to 756 pairs
(the ratio says so). The subset's fits must equal the sweep's to 1e-6 points. The CPU time of
the sweep (with its workers) and the load average are printed too: on a shared machine the
wall time alone says little.

Target (issue 11): the grid in <= 30 s on 2 cores (aim 10 s).

**No-knobs selection on a long record** (``BENCH_SWEEP_LONG`` samples, default 60000; 0 skips
it): ``sysid.auto.select`` with ``choose_focus`` (``sysid identify`` without
--past/--future/--order) on one record of a random 8-state system (m=4, l=6, white input,
innovation noise), one process. Printed: its wall and CPU time, the time up to the end of the
prediction-focus sweep (plan and feedback test included), of the simulation-focus sweep and
of the rest (the final identification), the longest wait between two progress calls after
the first, and the choice. Targets: <= 150 s at 60000 samples (124 s measured here), and
progress at least every 10 s (1 s measured).
Audit record (``n=8, m=4, l=6``, 90 % of it to ``select``) before/after the sweep stopped
measuring the stability cost of the models it drops and reported progress per model:
60000 samples 131 -> 112 s, 200000 samples 442 -> 368 s, the longest wait for progress
20 -> 4 s and 70 -> 12 s (the first call: plan and feedback test); about 80 % of what is
left is the simulation focus' output-error fits (``sysid/output_error.py``).
"""

from __future__ import annotations

import os
import time

import numpy as np

import sysid
from sysid.auto import plan, select_plan
from sysid.grid import pair_flights
from sysid.methods import DEFAULT_METHOD, get_method
from sysid.sweep import sweep
from tests.sysid.systems import open_loop, random_stable_system

__all__ = ["main"]

PASTS = range(25, 61)
FUTURES = range(5, 26)
ORDER = 8
WINDOW_S = 2.0


def _independent(data: sysid.IOData, val: sysid.IOData, pairs: list[tuple[int, int]], *,
                 method: str, **options: object) -> tuple[float, dict[tuple[int, int], np.ndarray]]:
    fits = {}
    meth = get_method(method)
    opts = meth.options(**options)
    t0 = time.perf_counter()
    for p, f in pairs:
        own = pair_flights([data], past=p, future=f, past_max=max(PASTS),
                           future_max=max(FUTURES))
        model = meth.identify(list(own), order=ORDER, past=p, future=f, options=opts)
        fits[(p, f)] = sysid.compare(model, val, window=WINDOW_S, warn=False).fit
    return time.perf_counter() - t0, fits


def _run(data: sysid.IOData, val: sysid.IOData, *, label: str, workers: int, subset: int,
         method: str = DEFAULT_METHOD, **options: object) -> bool:
    n_pairs = len(PASTS) * len(FUTURES)
    cpu0, t0 = os.times(), time.perf_counter()
    result = sweep(data, pasts=PASTS, futures=FUTURES, orders=[ORDER], validation=val,
                   window=WINDOW_S, workers=workers, method=method, **options)
    t_grid, cpu1 = time.perf_counter() - t0, os.times()
    cpu = sum(cpu1[:4]) - sum(cpu0[:4])  # user + system, this process and its workers
    all_pairs = [(r.past, r.future) for r in result.rows]
    pick = [all_pairs[i] for i in np.linspace(0, n_pairs - 1, subset).round().astype(int)]
    t_sub, fits = _independent(data, val, pick, method=method, **options)
    t_ind = t_sub * n_pairs / len(pick)
    by_pair = {(r.past, r.future): r.fit for r in result.rows}
    diff = max(float(np.max(np.abs(by_pair[k] - v))) for k, v in fits.items())
    best = result.best()
    print(f"  {label}: {n_pairs} pairs in {t_grid:6.2f} s with {workers} worker(s); "
          f"independent builds {t_ind:7.1f} s (1 process, {len(pick)} pairs timed, "
          f"{t_sub:.2f} s, extrapolated x{n_pairs / len(pick):.1f}): ratio "
          f"{t_ind / t_grid:5.1f}x")
    print(f"    sweep CPU time {cpu:.1f} s (this process and its workers; load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    print(f"    max |fit difference| sweep vs independent on the subset {diff:.1e} points; "
          f"selected past {best.past}, future {best.future}, score {best.score:.1f} %")
    return diff < 1e-6 and t_grid <= 30.0


LONG_TARGET_S = 150.0  # at 60000 samples
GAP_TARGET_S = 10.0


def _long_selection(n_samples: int) -> bool:
    """The no-knobs selection on one long record (module docstring): True when on target."""
    rng = np.random.default_rng(61)
    system = random_stable_system(n_states=8, n_inputs=4, n_outputs=6, rng=rng, dt=0.01)
    data = open_loop(system, n_samples=n_samples, rng=rng, noise_std=0.1).data
    meth = get_method("iem")
    cpu0, t0 = os.times(), time.perf_counter()
    ticks: list[tuple[float, int]] = []
    p = plan([[data]])
    sel = select_plan(p, method=meth, options=meth.options(), choose_focus=True,
                      choose_method=True,
                      progress=lambda done, _total: ticks.append((time.perf_counter(), done)))
    wall, cpu1 = time.perf_counter() - t0, os.times()
    cpu = sum(cpu1[:4]) - sum(cpu0[:4])
    times = [t for t, _ in ticks]
    first_run = next(t for t, done in ticks if done >= p.n_models) - t0
    gap = float(np.max(np.diff(times), initial=0.0))  # after the first model (plan, feedback)
    best = sel.best
    print(f"  no-knobs selection (IEM, both focuses, 1 process) on {n_samples} samples, "
          f"n=8 m=4 l=6: {wall:.1f} s wall, {cpu:.1f} s CPU; {p.n_models} models per focus: "
          f"plan and prediction {first_run:.1f} s, simulation "
          f"{times[-1] - t0 - first_run:.1f} s, "
          f"the rest {wall - (times[-1] - t0):.1f} s; longest wait between progress calls "
          f"{gap:.1f} s over {len(ticks)} calls")
    print(f"    chose past {best.past}, future {best.future}, order {best.order}, focus "
          f"{sel.model.provenance.get('focus')}, score {best.score:.2f} %")
    on_target = gap <= GAP_TARGET_S and (n_samples > 60000 or wall <= LONG_TARGET_S)
    print(f"    target (<= {LONG_TARGET_S:g} s at 60000 samples, progress every "
          f"<= {GAP_TARGET_S:g} s): {'met' if on_target else 'MISSED'}")
    return on_target


def main() -> int:
    """0 when the default IEM grid takes <= 30 s and equals the independent builds, and the
    long no-knobs selection is on target."""
    workers = int(os.environ.get("BENCH_SWEEP_WORKERS", "2"))
    subset = int(os.environ.get("BENCH_SWEEP_SUBSET", "24"))
    rng = np.random.default_rng(2024)
    system = random_stable_system(n_states=8, n_inputs=4, n_outputs=6, rng=rng)
    data = open_loop(system, n_samples=15000, rng=rng, noise_std=0.2).data
    val = open_loop(system, n_samples=15000, rng=rng, noise_std=0.2).data
    print(f"thesis-sized grid: pasts {PASTS.start}..{PASTS.stop - 1}, futures "
          f"{FUTURES.start}..{FUTURES.stop - 1}, order {ORDER}, n=8 m=4 l=6 N=15000, scored "
          f"by {WINDOW_S:g} s windowed simulation on another N=15000 record "
          f"(OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')})")
    ok = _run(data, val, label="IEM (default)", workers=workers, subset=subset)
    # PO-MOESP's default focus="simulation" fits B, D, x0 by output error over all samples
    # (about 0.9 s a model here, 756 models ~ 11 min of CPU): the grid shares only the
    # factorization, so it is timed with focus="prediction", whose realization the pair's
    # factor holds.
    _run(data, val, label="PO-MOESP focus=prediction", workers=workers, subset=subset,
         method="po-moesp", focus="prediction")
    print(f"  target (default IEM grid <= 30 s, equal to independent builds): "
          f"{'met' if ok else 'MISSED'}")
    long_samples = int(os.environ.get("BENCH_SWEEP_LONG", "60000"))
    if long_samples > 0:
        ok = _long_selection(long_samples) and ok
    return 0 if ok else 1
