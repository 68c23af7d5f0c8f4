"""Horizon and order sweeps (thesis sections 4.3.3 and 5.1.2-5.1.3).

The thesis chose past/future horizons by identifying "a number of system models with varying
past and future horizons, first in coarse increments and later in finer increments" (756
models) and the order from the singular values plus trials of orders 3-12. :func:`sweep` runs
such a grid: for each ``(past, future)`` pair the data products are built once (when the
method accepts ``products=``) and every order is realised from them; each model is scored
with :func:`sysid.validate.compare` on validation data (simulation, windowed simulation or
k-step prediction). Pairs run in parallel worker processes with ``workers > 1``.

Selection (:meth:`SweepResult.best`) is parsimonious: among successful (by default stable)
models, take the best mean fit :math:`F^*`, keep those within ``tol`` percentage points,
:math:`\\bar F \\ge F^* - \\text{tol}`, and return the one of smallest order (then best fit).
Orders above the true one fit the same data about as well, so "highest fit" alone would pick
an over-parameterised model at random.
"""

from __future__ import annotations

import concurrent.futures
import inspect
import itertools
import logging
import re
import signal
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sysid.data import IOData, as_flights
from sysid.errors import DataError, SysIdError
from sysid.model import StateSpaceModel
from sysid.validate import compare

__all__ = ["SweepResult", "SweepRow", "select_order", "sweep"]

log = logging.getLogger(__name__)

Identifier = Callable[..., StateSpaceModel]
Progress = Callable[[int, int], None]


@dataclass(frozen=True, eq=False)
class SweepRow:
    """One identified model of a sweep.

    ``fit`` (l,) percent on the validation data (NaN when identification failed),
    ``poles`` (n,) complex, ``seconds`` wall time of identification + validation,
    ``error`` the one-line reason when the model could not be identified.
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

    @property
    def mean_fit(self) -> float:
        """Mean of the per-channel fits, percent (NaN for failed rows)."""
        return float(np.mean(self.fit)) if self.error is None and self.fit.size else np.nan

    def to_record(self) -> dict[str, Any]:
        """JSON-able dict (poles as [re, im] pairs, fits in percent, time in seconds)."""
        return {
            "past": self.past, "future": self.future, "order": self.order,
            "fit_percent": [float(f) for f in self.fit], "mean_fit_percent": self.mean_fit,
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

    def best(self, *, tol: float = 0.5, require_stable: bool = True) -> SweepRow:
        """The parsimonious best row (module docstring): smallest order within ``tol`` points."""
        ok = [r for r in self.rows if r.error is None and np.isfinite(r.mean_fit)
              and (r.stable or not require_stable)]
        if not ok:
            raise DataError("no model of the sweep succeeded" +
                            (" and is stable" if require_stable else "") +
                            "; widen the grid or pass require_stable=False")
        top = max(r.mean_fit for r in ok)
        close = [r for r in ok if r.mean_fit >= top - tol]
        return min(close, key=lambda r: (r.order, -r.mean_fit))

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
    def fits(self) -> np.ndarray:
        """Per-channel fits of every row, (n_rows, l), percent."""
        return np.array([r.fit for r in self.rows])

    def table(self) -> str:
        """A plain-text table: horizons, order, mean fit, spectral radius, flags."""
        lines = [" past future order  fit[%]  max|pole|  stable  pred.stable"]
        for r in self.rows:
            if r.error is not None:
                lines.append(f"{r.past:5d} {r.future:6d} {r.order:5d}  failed: {r.error}")
                continue
            rad = float(np.max(np.abs(r.poles))) if r.poles.size else 0.0
            lines.append(f"{r.past:5d} {r.future:6d} {r.order:5d} {r.mean_fit:7.2f} "
                         f"{rad:10.4f}  {r.stable!s:6}  {r.predictor_stable!s}")
        return "\n".join(lines)


def _identifier(method: str | Identifier) -> tuple[str, Identifier]:
    if callable(method):
        return getattr(method, "__name__", "custom"), method
    import importlib

    known = {"iem": ("sysid.iem", "iem"), "po_moesp": ("sysid.moesp", "po_moesp")}
    if method not in known:
        raise DataError(f"method {method!r} is unknown; use 'iem', 'po_moesp' or a function")
    module, name = known[method]
    return method, getattr(importlib.import_module(module), name)


def _pair_task(
    *, data: tuple[IOData, ...], validation: tuple[IOData, ...], method: str | Identifier,
    past: int, future: int, orders: Sequence[int], options: dict[str, Any],
    horizon: int | None, window: float | None, keep_models: bool,
) -> list[SweepRow]:
    """Identify and score every order for one (past, future) pair (runs in a worker)."""
    _, fn = _identifier(method)
    ell = data[0].n_outputs
    kwargs = dict(options)
    params = inspect.signature(fn).parameters
    if "products" in params:  # one factorization of the data for all orders
        from sysid.factor import build_products

        try:
            kwargs["products"] = build_products(list(data), past=past, future=future)
        except SysIdError as exc:
            return [_failed(past, future, n, exc, 0.0, ell) for n in orders]
    rows = []
    for order in orders:
        t0 = time.perf_counter()
        try:
            model = fn(list(data), order=order, past=past, future=future, **kwargs)
            res = compare(model, list(validation), horizon=horizon, window=window,
                          warn=False)
        except (SysIdError, np.linalg.LinAlgError) as exc:
            rows.append(_failed(past, future, order, exc, time.perf_counter() - t0, ell))
            continue
        rows.append(SweepRow(
            past=past, future=future, order=order, fit=res.fit, poles=model.poles(),
            stable=model.is_stable, predictor_stable=model.predictor_is_stable,
            seconds=time.perf_counter() - t0, model=model if keep_models else None))
    return rows


def _failed(past: int, future: int, order: int, exc: Exception, seconds: float,
            n_outputs: int) -> SweepRow:
    msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
    return SweepRow(past=past, future=future, order=order, fit=np.full(n_outputs, np.nan),
                    poles=np.array([], dtype=complex), stable=False, predictor_stable=False,
                    seconds=seconds, error=msg)


def sweep(
    data: IOData | Sequence[IOData],
    *,
    pasts: Sequence[int],
    futures: Sequence[int],
    orders: Sequence[int],
    method: str | Identifier = "iem",
    validation: IOData | Sequence[IOData] | None = None,
    horizon: int | None = None,
    window: float | None = None,
    workers: int = 1,
    progress: Progress | None = None,
    keep_models: bool = False,
    **options: Any,
) -> SweepResult:
    """Identify a model for every (past, future, order) and score it on validation data.

    ``method`` is ``"iem"``, ``"po_moesp"`` or a function with the signature of
    :func:`sysid.iem`; ``options`` go to it (e.g. ``feedthrough=False``). ``validation``
    defaults to the identification data; ``horizon``/``window`` choose how models are compared
    (see :func:`sysid.compare`). ``workers > 1`` runs (past, future) pairs in that many
    processes. ``progress(done, total)`` is called in this process after each pair, with
    counts of models. ``keep_models`` keeps every model in its row (memory!).
    """
    flights = as_flights(data)
    val = flights if validation is None else as_flights(validation)
    name, _ = _identifier(method)
    pairs = [(int(p), int(f)) for p in pasts for f in futures]
    orders = [int(n) for n in orders]
    if not pairs or not orders:
        raise DataError("empty sweep grid; give at least one past, future and order")
    total, done = len(pairs) * len(orders), 0
    common = {"data": flights, "validation": val, "method": method, "orders": orders,
              "options": options, "horizon": horizon, "window": window,
              "keep_models": keep_models}
    results: dict[tuple[int, int], list[SweepRow]] = {}
    t0 = time.perf_counter()
    if workers <= 1:
        for p, f in pairs:
            results[(p, f)] = _pair_task(past=p, future=f, **common)
            done += len(orders)
            if progress is not None:
                progress(done, total)
    else:
        def finished(pair: tuple[int, int], pair_rows: list[SweepRow]) -> None:
            nonlocal done
            results[pair] = pair_rows
            done += len(orders)
            if progress is not None:
                progress(done, total)

        _run_parallel(pairs, common, workers=workers, finished=finished)
    rows = tuple(row for pair in pairs for row in results[pair])
    n_failed = sum(r.error is not None for r in rows)
    log.info("sweep of %d models (%d failed) in %.1f s", len(rows), n_failed,
             time.perf_counter() - t0)
    return SweepResult(rows=rows, method=name, horizon=horizon, window=window)


def _ignore_sigint() -> None:
    """Worker initializer: Ctrl-C is the parent's to handle (it stops the pool)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_parallel(pairs: list[tuple[int, int]], common: dict[str, Any], *, workers: int,
                  finished: Callable[[tuple[int, int], list[SweepRow]], None]) -> None:
    """Run the pairs in worker processes, calling ``finished(pair, rows)`` as each ends.

    On any exception in this process (Ctrl-C included) pending pairs are cancelled and the
    workers terminated before it propagates, so an interrupted sweep ends at once.
    """
    n_workers = min(workers, len(pairs))
    pool = concurrent.futures.ProcessPoolExecutor(max_workers=n_workers,
                                                  initializer=_ignore_sigint)
    todo = iter(pairs)
    running: dict[concurrent.futures.Future, tuple[int, int]] = {}

    def top_up() -> None:
        # At most two pairs per worker in flight: submitting hundreds at once can fill the
        # executor's wake-up pipe and deadlock it under load (CPython gh-105829), and a short
        # queue leaves little to cancel.
        for p, f in itertools.islice(todo, 2 * n_workers - len(running)):
            running[pool.submit(_pair_task, past=p, future=f, **common)] = (p, f)

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
        pool.shutdown(wait=False, cancel_futures=True)
        for proc in procs:
            if proc.is_alive():
                proc.terminate()
        for proc in procs:
            proc.join(timeout=5)
        raise
    pool.shutdown(wait=True)


def select_order(
    data: IOData | Sequence[IOData],
    *,
    past: int,
    future: int,
    orders: Sequence[int],
    tol: float = 0.5,
    **kwargs: Any,
) -> tuple[SweepRow, SweepResult]:
    """Order selection at fixed horizons: ``(best row, full sweep)`` (see :func:`sweep`)."""
    result = sweep(data, pasts=[past], futures=[future], orders=orders, **kwargs)
    return result.best(tol=tol), result
