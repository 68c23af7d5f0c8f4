"""Horizon and order sweeps (thesis sections 4.3.3 and 5.1.2-5.1.3).

The thesis chose past/future horizons by identifying "a number of system models with varying
past and future horizons, first in coarse increments and later in finer increments" (756
models) and the order from the singular values plus trials of orders 3-12. :func:`sweep` runs
such a grid with one factorization (:mod:`sysid.grid`): the Gram matrix of the largest Hankel
matrix is formed once, every pair ``(p, f)`` is its time-aligned sub-block (the same common
columns for every pair), IEM shares one Cholesky factor among the futures of a past, and every
order is realised from the pair's products. Each model is scored with
:func:`sysid.validate.compare` on validation data (simulation, windowed simulation or k-step
prediction). Pasts run in parallel worker processes with ``workers > 1``, or on a Dask
cluster with ``client=`` (:mod:`sysid.cluster`: the grid is scattered to the workers once,
and again if the workers holding it leave).

**Score.** A model is ranked by its *score*: the mean over the output channels of the fit
floored at 0 %, :math:`S = \\frac1l \\sum_i \\max(F_i, 0)`. A channel no model can predict
(fits of -200 % or -600 %) then counts as 0 for every model and cannot decide the ranking,
while the mean fit would be dominated by it.

Selection (:meth:`SweepResult.best`) is parsimonious: among successful (by default stable)
models, take the best score :math:`S^*`, keep those within one standard error of it,
:math:`S \\ge S^* - \\max(\\widehat{\\mathrm{se}}(S^*),\\ 0.1)`, the standard error from the
score's blocks of validation data (the one-standard-error rule, :mod:`sysid.parsimony`), and
return the one of smallest order (then best score); ``best(tol=...)`` keeps those within a
fixed ``tol`` points instead. Orders above the true one fit the same data about as well, so
"highest fit" alone would pick an over-parameterised model at random. :func:`sysid.auto.select`
(what ``sysid identify`` and ``sysid sweep`` run) adds the held-out split, the default grid,
the choice of focus and the final identification on all the data.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import itertools
import logging
import re
import signal
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import threadpoolctl

from sysid.data import IOData, as_flights
from sysid.errors import DataError, ParameterError, SysIdError, first_line
from sysid.factor import DataProducts, grid_values
from sysid.grid import HorizonGrid, build_grid, grid_products
from sysid.iem import without_stability_cost
from sysid.innovation_cov import without_own_noise_cov
from sysid.methods import DEFAULT_METHOD, Method, Options, get_method, method_loggers
from sysid.model import StateSpaceModel
from sysid.parsimony import block_errors, block_shares, parsimonious
from sysid.validate import compare

__all__ = ["SweepResult", "SweepRow", "one_blas_thread", "quiet_models", "select_order",
           "sweep"]

log = logging.getLogger(__name__)

Progress = Callable[[int, int], None]


@dataclass(frozen=True, eq=False)
class SweepRow:
    """One identified model of a sweep.

    ``fit`` (l,) percent on the validation data (NaN when identification failed),
    ``poles`` (n,) complex, ``seconds`` wall time of identification + validation,
    ``error`` the one-line reason when the model could not be identified, ``errors`` (B, l)
    the squared errors of the score per block of the validation data
    (:func:`sysid.parsimony.block_errors`; None for failed and hand-made rows), ``shares``
    (B,) each block's share of the validation samples (:func:`sysid.parsimony.block_shares`).
    """

    past: int
    future: int
    order: int
    fit: np.ndarray
    poles: np.ndarray
    stable: bool
    predictor_stable: bool
    seconds: float
    error: str | None = None
    model: StateSpaceModel | None = field(default=None, repr=False)
    errors: np.ndarray | None = field(default=None, repr=False)
    shares: np.ndarray | None = field(default=None, repr=False)

    @property
    def mean_fit(self) -> float:
        """Mean of the per-channel fits, percent (NaN for failed rows)."""
        return float(np.mean(self.fit)) if self.error is None and self.fit.size else np.nan

    @property
    def score(self) -> float:
        """Mean of the per-channel fits floored at 0 %, percent (module docstring; NaN for
        failed rows and models whose output diverged)."""
        if self.error is not None or not self.fit.size or np.isnan(self.fit).any():
            return np.nan
        return float(np.mean(np.clip(self.fit, 0.0, None)))

    def to_record(self) -> dict[str, Any]:
        """JSON-able dict (poles as [re, im] pairs, fits in percent, time in seconds)."""
        return {
            "past": self.past, "future": self.future, "order": self.order,
            "fit_percent": [float(f) for f in self.fit], "mean_fit_percent": self.mean_fit,
            "score_percent": self.score,
            "poles": [[float(p.real), float(p.imag)] for p in self.poles],
            "stable": self.stable, "predictor_stable": self.predictor_stable,
            "seconds": self.seconds, "error": self.error,
        }


@dataclass(frozen=True, eq=False)
class SweepResult:
    """All rows of a sweep, in (past, future, order) order, and how they were scored."""

    rows: tuple[SweepRow, ...]
    method: str
    horizon: int | None
    window: float | None
    #: Seconds of the longest validation record (a window at least that long simulates each
    #: record whole); None when not known.
    record_s: float | None = None

    def best(self, *, tol: float | None = None, require_stable: bool = True) -> SweepRow:
        """The parsimonious best row (module docstring): the smallest order within one standard
        error of the best score (:func:`sysid.parsimony.parsimonious`), or within ``tol``
        points of it when a fixed ``tol`` is given."""
        ok = self.ranked(require_stable=require_stable)
        if not ok:
            raise DataError("no model of the sweep succeeded" +
                            (" and is stable" if require_stable else "") +
                            "; widen the grid or pass require_stable=False")
        return parsimonious(ok, tol=tol)

    def ranked(self, *, require_stable: bool = False) -> list[SweepRow]:
        """Successful rows (and stable ones only, with ``require_stable``), best score first."""
        ok = [r for r in self.rows if r.error is None and np.isfinite(r.score)
              and (r.stable or not require_stable)]
        return sorted(ok, key=lambda r: -r.score)

    def failures(self) -> list[tuple[str, int]]:
        """Why models failed: ``(message, count)``, most common first. Messages that differ only
        in their numbers (horizons, orders, ranks) count as one; the first one is shown."""
        counts: Counter[str] = Counter()
        example: dict[str, str] = {}
        for r in self.rows:
            if r.error is not None:
                key = re.sub(r"\d+(\.\d+)?(e[-+]?\d+)?", "#", r.error)
                counts[key] += 1
                example.setdefault(key, r.error)
        return [(example[k], n) for k, n in counts.most_common()]

    @property
    def scoring(self) -> str:
        """How the rows were scored, for people: ``"1-step prediction"``, ``"simulation over
        2 s windows"`` or ``"simulation of each whole record"``."""
        if self.horizon is not None:
            return f"{self.horizon}-step prediction"
        if self.window is not None and (self.record_s is None or self.window < self.record_s):
            return f"simulation over {self.window:.3g} s windows"
        return "simulation of each whole record"

    @property
    def fits(self) -> np.ndarray:
        """Per-channel fits of every row, (n_rows, l), percent."""
        return np.array([r.fit for r in self.rows])

    def table(self) -> str:
        """A plain-text table: horizons, order, mean fit, spectral radius, flags."""
        lines = [" past future order score[%] fit[%]  max|pole|  stable  pred.stable"]
        for r in self.rows:
            if r.error is not None:
                lines.append(f"{r.past:5d} {r.future:6d} {r.order:5d}  failed: {r.error}")
                continue
            rad = float(np.max(np.abs(r.poles))) if r.poles.size else 0.0
            lines.append(f"{r.past:5d} {r.future:6d} {r.order:5d} {r.score:8.2f} "
                         f"{r.mean_fit:7.2f} "
                         f"{rad:10.4f}  {r.stable!s:6}  {r.predictor_stable!s}")
        return "\n".join(lines)


def _past_task(
    *, grid: HorizonGrid, validation: tuple[IOData, ...], method: Method, options: Options,
    past: int, futures: Sequence[int], orders: Sequence[int], horizon: int | None,
    window: float | None, keep_models: bool, row_done: Callable[[int], None] | None = None,
) -> list[SweepRow]:
    """Identify and score every (future, order) for one past (runs in a worker): the pairs
    share the grid's Gram matrix and, for IEM, one factor (:mod:`sysid.grid`).
    ``row_done(k)`` (this process only) is called after the k-th row of the past.

    BLAS runs on one thread here (:func:`one_blas_thread`): a multi-threaded BLAS sums in an
    order that depends on its thread count, so a row would differ in its last bits between
    this process, a worker process and a Dask worker (which runs one BLAS thread).
    Models the sweep does not keep skip the measurement of what their stability step cost
    (:func:`sysid.iem.without_stability_cost`): it is provenance only, and a second
    identification and two runs over the identification data for each model whose poles
    were moved; and the covariance of their own one-step errors
    (:func:`sysid.innovation_cov.without_own_noise_cov`: a run of the predictor over the
    data, half to two thirds of the identification at the thesis size)."""
    with one_blas_thread(), quiet_models(), contextlib.ExitStack() as unmeasured:
        if not keep_models:
            unmeasured.enter_context(without_stability_cost())
            unmeasured.enter_context(without_own_noise_cov())
        return _past_rows(grid=grid, validation=validation, method=method, options=options,
                          past=past, futures=futures, orders=orders, horizon=horizon,
                          window=window, keep_models=keep_models, row_done=row_done)


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Limit BLAS/OpenMP to one thread inside the block (restored after)."""
    with threadpoolctl.threadpool_limits(limits=1):
        yield


@contextlib.contextmanager
def quiet_models() -> Iterator[None]:
    """Per-model warnings (a skipped refinement, a pole kept outside the unit circle, ...) of
    the many models of a grid would flood the log; a sweep reports failures in its rows.
    Only errors of the methods' modules (:func:`sysid.methods.method_loggers`) and of the
    modules they use pass inside the block."""
    names = (*method_loggers(), "sysid.realize", "sysid.factor", "sysid.pem", "sysid.finish",
             "sysid.stability")
    loggers = [logging.getLogger(n) for n in names]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(max(lg.getEffectiveLevel(), logging.ERROR))
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def _past_rows(
    *, grid: HorizonGrid, validation: tuple[IOData, ...], method: Method, options: Options,
    past: int, futures: Sequence[int], orders: Sequence[int], horizon: int | None,
    window: float | None, keep_models: bool, row_done: Callable[[int], None] | None = None,
) -> list[SweepRow]:
    ell = grid.n_outputs
    products = grid_products(grid, past=past, futures=futures,
                             shared_iem=method.shares_futures,
                             feedthrough=bool(getattr(options, "feedthrough", False)))
    rows = []
    for future in futures:
        pair = products[future]
        for order in orders:
            rows.append(_row(pair, past=past, future=future, order=order, method=method,
                             options=options, validation=validation, horizon=horizon,
                             window=window, keep_models=keep_models, n_outputs=ell))
            if row_done is not None:
                row_done(len(rows))
    return rows


def _row(pair: DataProducts | SysIdError, *, past: int, future: int, order: int,
         method: Method, options: Options, validation: tuple[IOData, ...],
         horizon: int | None, window: float | None, keep_models: bool, n_outputs: int
         ) -> SweepRow:
    """One model of the pair identified and scored (a failed row if it cannot be)."""
    t0 = time.perf_counter()
    if isinstance(pair, SysIdError):
        return _failed(past, future, order, pair, 0.0, n_outputs)
    try:
        model = method.identify(None, order=order, past=past, future=future,
                                options=options, products=pair)
        res = compare(model, list(validation), horizon=horizon, window=window, warn=False)
    except (SysIdError, np.linalg.LinAlgError) as exc:
        return _failed(past, future, order, exc, time.perf_counter() - t0, n_outputs)
    return SweepRow(
        past=past, future=future, order=order, fit=res.fit, poles=model.poles(),
        stable=model.is_stable, predictor_stable=model.predictor_is_stable,
        seconds=time.perf_counter() - t0, model=model if keep_models else None,
        errors=block_errors(res), shares=block_shares(res))


def _failed(past: int, future: int, order: int, exc: Exception, seconds: float,
            n_outputs: int) -> SweepRow:
    return SweepRow(past=past, future=future, order=order, fit=np.full(n_outputs, np.nan),
                    poles=np.array([], dtype=complex), stable=False, predictor_stable=False,
                    seconds=seconds, error=first_line(exc))


def sweep(
    data: IOData | Sequence[IOData],
    *,
    pasts: Sequence[int],
    futures: Sequence[int],
    orders: Sequence[int],
    method: str | Method = DEFAULT_METHOD,
    options: Options | None = None,
    validation: IOData | Sequence[IOData] | None = None,
    horizon: int | None = None,
    window: float | None = None,
    workers: int = 1,
    progress: Progress | None = None,
    keep_models: bool = False,
    client: Any | None = None,
    **option_values: Any,
) -> SweepResult:
    """Identify a model for every (past, future, order) and score it on validation data.

    ``method`` is a name or a :class:`~sysid.methods.Method` of :mod:`sysid.methods`;
    ``options`` its options object, or give them as keywords (``feedthrough=False``).
    Every pair uses the common Hankel columns of the grid (:mod:`sysid.grid`): the model of
    ``(p, f)`` is the one identified on ``sysid.grid.pair_flights(...)``. ``validation``
    defaults to the identification data; ``horizon``/``window`` choose how models are compared
    (see :func:`sysid.compare`). ``workers > 1`` runs the pasts in that many processes.
    ``client`` (a :class:`distributed.Client`) runs the pasts on that Dask cluster instead,
    the grid and validation data scattered to the workers (again if they leave:
    :mod:`sysid.cluster`); the rows
    are the same as locally. ``progress(done, total)`` is called in this process with counts
    of models: after each model when the sweep runs here (``workers=1``, no ``client``), after
    each past otherwise. ``keep_models`` keeps every model in its row (memory!), with what
    its stability step cost measured (:func:`sysid.iem.without_stability_cost`).
    """
    meth = get_method(method)
    if options is not None and option_values:
        raise ParameterError("give the options either as an options object or as keywords")
    opts = options if options is not None else meth.options(**option_values)
    flights = as_flights(data)
    val = flights if validation is None else as_flights(validation)
    pasts = sorted(set(grid_values("pasts", pasts, low=1)))
    futures = sorted(set(grid_values("futures", futures, low=2)))
    orders = grid_values("orders", orders, low=1)
    if not pasts or not futures or not orders:
        raise DataError("empty sweep grid; give at least one past, future and order")
    grid = build_grid(flights, past_max=pasts[-1], future_max=futures[-1])
    total, done = len(pasts) * len(futures) * len(orders), 0
    common = {"grid": grid, "validation": val, "method": meth, "options": opts,
              "futures": futures, "orders": orders, "horizon": horizon, "window": window,
              "keep_models": keep_models}
    results: dict[int, list[SweepRow]] = {}
    t0 = time.perf_counter()

    def finished(past: int, past_rows: list[SweepRow], *, reported: bool = False) -> None:
        nonlocal done
        results[past] = past_rows
        done += len(past_rows)
        if progress is not None and not reported:
            progress(done, total)

    if client is not None:
        from sysid.cluster import run_pasts

        shared = {k: common.pop(k) for k in ("grid", "validation")}
        run_pasts(client, task=_past_task, shared=shared, common=common, pasts=pasts,
                  finished=finished)
    elif workers <= 1:  # progress after each model: one may take seconds (simulation focus)
        for p in pasts:
            tick = None if progress is None else (
                lambda k, base=done: progress(base + k, total))
            finished(p, _past_task(past=p, row_done=tick, **common), reported=tick is not None)
    else:
        _run_parallel(pasts, common, workers=workers, finished=finished)
    rows = tuple(row for p in pasts for row in results[p])
    n_failed = sum(r.error is not None for r in rows)
    log.info("sweep of %d models (%d failed) in %.1f s", len(rows), n_failed,
             time.perf_counter() - t0)
    return SweepResult(rows=rows, method=meth.name, horizon=horizon, window=window,
                       record_s=max(d.n_samples * d.dt for d in val))


def _ignore_sigint() -> None:
    """Worker initializer: Ctrl-C is the parent's to handle (it stops the pool)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _unblock_manager(pool: concurrent.futures.ProcessPoolExecutor) -> None:
    """After the workers were terminated: a worker stopped in the middle of sending its result
    leaves half a message, which the executor's manager thread waits for forever, and the
    call queue's feeder thread may be blocked writing a task no worker will read. The
    interpreter's exit joins the manager (``_python_exit``), so the interrupted command hung
    after printing its error (seen under load, 1 run in 6). Closing this process's end of the
    result pipe's writer makes that wait end (EOF: the manager marks the pool broken and
    stops), and the feeder is not waited for. CPython internals, each looked up with care."""
    call_queue = getattr(pool, "_call_queue", None)
    if call_queue is not None and hasattr(call_queue, "cancel_join_thread"):
        call_queue.cancel_join_thread()
    writer = getattr(getattr(pool, "_result_queue", None), "_writer", None)
    if writer is not None:
        with contextlib.suppress(OSError):
            writer.close()


def _run_parallel(pasts: list[int], common: dict[str, Any], *, workers: int,
                  finished: Callable[[int, list[SweepRow]], None]) -> None:
    """Run the pasts in worker processes, calling ``finished(past, rows)`` as each ends.

    On any exception in this process (Ctrl-C included) pending pasts are cancelled and the
    workers terminated before it propagates, so an interrupted sweep ends at once.
    """
    n_workers = min(workers, len(pasts))
    pool = concurrent.futures.ProcessPoolExecutor(max_workers=n_workers,
                                                  initializer=_ignore_sigint)
    todo = iter(pasts)
    running: dict[concurrent.futures.Future, int] = {}

    def top_up() -> None:
        # At most two pasts per worker in flight: submitting hundreds at once can fill the
        # executor's wake-up pipe and deadlock it under load (CPython gh-105829), and a short
        # queue leaves little to cancel.
        for p in itertools.islice(todo, 2 * n_workers - len(running)):
            running[pool.submit(_past_task, past=p, **common)] = p

    try:
        top_up()
        while running:
            done, _ = concurrent.futures.wait(running, timeout=0.5,
                                              return_when=concurrent.futures.FIRST_COMPLETED)
            for fut in done:
                finished(running.pop(fut), fut.result())
            top_up()
    except BaseException:
        procs = list((getattr(pool, "_processes", None) or {}).values())
        manager = getattr(pool, "_executor_manager_thread", None)  # shutdown forgets it
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        for proc in procs:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.kill()
                proc.join(timeout=5)
        _unblock_manager(pool)
        # let the executor's manager thread see its workers gone and close its wake-up pipe:
        # else the interpreter's exit hook may write to that pipe as it closes and print a
        # traceback after Ctrl-C (CPython 3.11 concurrent.futures.process._python_exit)
        if manager is not None:
            manager.join(timeout=5)
        raise
    pool.shutdown(wait=True)


def select_order(
    data: IOData | Sequence[IOData],
    *,
    past: int,
    future: int,
    orders: Sequence[int],
    tol: float | None = None,
    **kwargs: Any,
) -> tuple[SweepRow, SweepResult]:
    """Order selection at fixed horizons: ``(best row, full sweep)`` (see :func:`sweep`)."""
    result = sweep(data, pasts=[past], futures=[future], orders=orders, **kwargs)
    return result.best(tol=tol), result
