"""Live identification while flying: a flight listener that feeds the IEM engine of
:mod:`sysid.live` during the excitation and records every update (``docs/live-id.md``).

**Threads.** :meth:`LiveIdListener.rows` runs on the runner's thread and only appends the rows
of the selected log streams (and the phase markers) to a bounded queue (drop-oldest, counted in
``dropped_batches``); it never blocks and never raises. Everything else runs on the listener's
own worker thread: zero-order hold onto the grid, :meth:`LiveIdentifier.append`, the updates.
The runner collects the worker's results with :meth:`poll` (rows of the ``live_id`` stream for
the recorder, and a request to end the excitation once converged) and, after the stop setpoint,
:meth:`finish` waits (bounded) for the final update and saves the model next to the session.
No identification code is imported here: the caller hands the engine in (:class:`Engine`,
built by ``groundstation fly``), so flying without live identification loads none.

**Data** (:class:`~groundstation.flight.liveid_data.ExcitationGrid`). The window is the
recorded excitation, from the first excitation phase marker to the
marker of the first phase after the last excitation phase (an abort ends it too): log rows
whose host time falls inside it. The grid is :math:`g_j = g_0 + j\\,\\Delta t` on firmware
time, :math:`g_0` the latest first firmware time of the selected streams in the window and
:math:`\\Delta t` their (common) logged period; a grid instant is used once every stream has a
sample at or after it, each channel holding its latest sample at or before it (the zero-order
hold of :func:`sysid.preprocess.zoh_resample`, as offline). The samples identified are
therefore exactly those :func:`sysid.preprocess.iodata_from_streams` builds from the session
file on ``[g_0, g_{N-1}]``, and the final model equals ``sysid.iem`` of them (mean removed).

**Updates** are due every ``update_period`` seconds of flight time from the start of the
window, once there are enough samples. One that comes due while the previous one still runs is
skipped (counted): the worker falls behind, never the flight. Each update records the flight
time, data span, order, horizons, the poles, the largest pole magnitude, the pole movement (the
Hausdorff distance to the previous update's poles: every pole within that distance of one of
the other set, and back), and the one-step-ahead fit and normalised innovation variance on the
last :data:`FIT_WINDOW_S` seconds. When the excitation ends, a final update uses every sample.

**Converged** (:class:`Convergence`, ``--until-converged``;
:mod:`~groundstation.flight.liveid_update`): the current poles lie within
``tolerance`` (Hausdorff distance) of those of every update of the last ``duration_s`` seconds,
at least two of them older than the current one and one ``duration_s`` or more ago. The runner
then ends the excitation at its next setpoint and flies the rest of the plan (its landing).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cfsession.schema import StreamSpec, live_id_spec
from groundstation.flight.liveid_data import (
    Channel,
    ExcitationGrid,
    check_live_id,
    planned_streams,
    resolve_channels,
)
from groundstation.flight.liveid_update import (
    Convergence,
    Update,
    converged,
    finite_mean,
    pole_move,
    sorted_poles,
)
from groundstation.plan import LiveIdConfig

__all__ = ["FIT_WINDOW_S", "Channel", "Convergence", "Engine", "LiveIdListener", "Update",
           "check_live_id", "planned_streams", "resolve_channels"]

log = logging.getLogger(__name__)

FIT_WINDOW_S = 5.0
"""Seconds of the most recent data the one-step fit and innovation variance are measured on."""
FINISH_TIMEOUT_S = 30.0
"""Longest wait (wall s, after the stop setpoint) for the final update."""


@dataclass(frozen=True)
class Engine:
    """The identification the worker drives, handed in by a caller that may import ``sysid``
    (``groundstation.commands.fly.live_id_engine``): ``identifier`` builds a
    ``sysid.live.LiveIdentifierProcess`` (the engine in a child process: an update never
    holds this interpreter's lock, which the setpoint thread needs on time), ``zoh`` is
    ``sysid.preprocess.zoh_resample`` and ``save_model`` ``sysid.model_io.save``."""

    identifier: Callable[..., Any]
    zoh: Callable[..., np.ndarray]
    save_model: Callable[[Any, Path], Path]


class LiveIdListener:
    """A flight listener (and the runner's source of ``live_id`` rows); module docstring.

    ``observers`` get ``begin(listener=self, streams=streams)`` once and ``update(update=)``
    (an :class:`Update`) from the worker thread; one that raises is dropped. ``status`` is a
    one-line summary of the last update for progress displays; :attr:`caught_up` says whether
    the worker has handled every batch queued so far.
    """

    def __init__(self, *, config: LiveIdConfig, engine: Engine,
                 convergence: Convergence | None = None, observers: Sequence[Any] = (),
                 fit_window_s: float = FIT_WINDOW_S, queue_batches: int = 4096,
                 finish_timeout_s: float = FINISH_TIMEOUT_S) -> None:
        self.config, self.engine, self.convergence = config, engine, convergence
        self.observers = list(observers)
        self.fit_window_s, self.finish_timeout_s = fit_window_s, finish_timeout_s
        self._inbox: deque[tuple[str, Sequence[tuple]]] = deque(maxlen=queue_batches)
        self._outbox: deque[tuple] = deque()
        self._wake, self._stop = threading.Event(), threading.Event()
        self._thread: threading.Thread | None = None
        self._wanted: set[str] = set()
        self.dropped_batches = 0
        self._queued = self._handled = 0  # batches queued by rows(); handled by the worker
        self.updates = self.skipped = self.failed = 0
        self.status = "live id: waiting for the excitation"
        self.error = ""
        self.inputs: list[Channel] = []
        self.outputs: list[Channel] = []
        self.dt = 0.0
        self.final: Update | None = None
        self.final_model: Any = None
        self.converged_at: float | None = None
        self._end_reason = ""
        self._reported = False

    # ------------------------------------------------------------ runner's thread
    def streams(self) -> list[StreamSpec]:
        """The stream this listener adds to the session (declared before the file exists)."""
        c = self.config
        return [live_id_spec(order=c.order, attrs={
            "inputs": ",".join(c.inputs), "outputs": ",".join(c.outputs), "order": c.order,
            "past": c.past, "future": c.future, "update_period_s": c.update_period,
            "fit_window_s": self.fit_window_s})]

    def begin(self, *, streams: Sequence[StreamSpec], metadata: Mapping[str, Any]) -> None:
        self.inputs, self.outputs, self.dt = check_live_id(self.config, streams=streams)
        table = metadata.get("phase_table") or []
        exc = [int(p["id"]) for p in table if p.get("kind") == "excitation"]
        self._grid = ExcitationGrid(channels=self.inputs + self.outputs, streams=streams,
                                    last_excitation=max(exc) if exc else None, dt=self.dt,
                                    zoh=self.engine.zoh)
        c = self.config
        self.ident = self.engine.identifier(
            n_inputs=len(self.inputs), n_outputs=len(self.outputs), order=c.order,
            past=c.past, future=c.future, dt=self.dt,
            input_names=tuple(x.label for x in self.inputs),
            output_names=tuple(x.label for x in self.outputs),
            input_units=tuple(x.unit for x in self.inputs),
            output_units=tuple(x.unit for x in self.outputs))
        self._next_due: float | None = None
        self._history: list[tuple[float, np.ndarray]] = []
        self._last_n = 0
        self._wanted = {*self._grid.feeds, "phases"}
        for obs in list(self.observers):
            self._notify(obs, "begin", listener=self, streams=streams)
        if self._grid.last_excitation is None:
            self.status = "live id: the plan has no excitation phase; nothing to identify"
        self._thread = threading.Thread(target=self._run, name="live-id", daemon=True)
        self._thread.start()

    def rows(self, stream: str, rows: Sequence[tuple]) -> None:
        """Queue rows of a selected stream (never blocks; a full queue drops its oldest)."""
        if stream in self._wanted and rows:
            if len(self._inbox) == self._inbox.maxlen:
                self.dropped_batches += 1
            self._inbox.append((stream, rows))
            self._queued += 1
            self._wake.set()

    def in_step(self, *, timeout_s: float = 2.5,
                real_time_s: float | None = None) -> Callable[[int], None]:
        """A tick hook holding each setpoint until the worker has handled the rows so far
        (:attr:`caught_up`; at most ``timeout_s`` of wall time). ``sim://`` paces its clock on
        the runner, so a simulated flight runs in step with the identification however busy
        the host: every due update is computed. ``fly`` uses it on a flat-out simulator
        (``speed=inf``), where the identification could otherwise never keep up; a real
        flight never waits on it. With ``real_time_s`` (the setpoint period) setpoint ``k`` is
        held no later than ``k`` periods after the first: the flight is never slower than
        real time, and updates slower than that are skipped as in a real flight (an order of
        200 held each setpoint 2.5 s)."""
        first: list[float] = []

        def hook(k: int) -> None:
            now = time.monotonic()
            give_up = now + timeout_s
            if real_time_s is not None:
                if not first:
                    first.append(now - k * real_time_s)
                give_up = min(give_up, first[0] + k * real_time_s)
            while not self.caught_up and time.monotonic() < give_up:
                time.sleep(0.001)

        return hook

    @property
    def caught_up(self) -> bool:
        """Whether the worker has taken every batch queued so far and run the update that
        came due with them (or skipped it); False while it works. A flight on a paced clock
        (``sim://``) can wait on it to run in step with the identification (the tests do)."""
        alive = self._thread is not None and self._thread.is_alive()
        return not alive or self._handled >= self._queued

    def poll(self) -> tuple[list[tuple[str, list[tuple]]], str]:
        """Rows of the ``live_id`` stream since the last call, and (once) why the excitation
        should end now ('' while not converged)."""
        rows = []
        while self._outbox:
            rows.append(self._outbox.popleft())
        reason = ""
        if self._end_reason and not self._reported:
            self._reported, reason = True, self._end_reason
        return ([("live_id", rows)] if rows else []), reason

    def finish(self, *, path: Path) -> dict[str, Any]:
        """After the stop: wait (bounded) for the final update, save the model next to the
        session (``STEM.live-model.json``); returns the summary's ``live_id`` entry."""
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=self.finish_timeout_s)
            if self._thread.is_alive():
                self.error = (self.error or
                              f"final update unfinished after {self.finish_timeout_s:g} s")
        model_file = ""
        if self.final_model is not None:
            target = path.with_name(f"{path.stem}.live-model.json")
            prov = {**self.final_model.provenance, "live_id": {
                "session": path.name, "fw_start_s": self._grid.g0, "dt": self.dt,
                "n_samples": self.final.n_samples, "flight_time_s": self.final.t,
                "channels": {c.label: f"{c.stream}.{c.field}" for c in self.inputs + self.outputs}}}
            try:
                self.engine.save_model(self.final_model.replace(provenance=prov), target)
                model_file = target.name
            except Exception as exc:
                log.exception("live id: saving the model failed")
                self.error = f"model not saved ({type(exc).__name__}: {exc})"
        f = self.final
        return {"live_id": {
            "updates": self.updates, "skipped": self.skipped, "failed": self.failed,
            "dropped_batches": self.dropped_batches, "order": self.config.order,
            "past": self.config.past, "future": self.config.future, "dt_s": self.dt,
            "final_t_s": None if f is None else round(f.t, 3),
            "span_s": None if f is None else round(f.span_s, 3),
            "fit_pct": None if f is None else round(f.fit_pct, 2),
            "fit_window_s": self.fit_window_s,
            "max_pole": None if f is None else round(float(np.abs(f.poles).max()), 6),
            "converged_at_s": self.converged_at, "model_file": model_file, "error": self.error,
            "convergence": None if self.convergence is None else {
                "tolerance": self.convergence.tolerance,
                "duration_s": self.convergence.duration_s}}}

    def end(self, *, summary: Mapping[str, Any]) -> None:
        self._stop.set()
        self._wake.set()
        if self._thread is not None:
            self._thread.join(timeout=self.finish_timeout_s)

    # ------------------------------------------------------------ worker thread
    def _run(self) -> None:
        try:
            self._loop()
        except Exception as exc:  # a bug here (or a dead engine) must never reach the flight
            if isinstance(exc, EOFError | OSError):  # the engine's process ended: no bug here
                log.error("live id worker failed: the identification process ended (%s: %s)",
                          type(exc).__name__, exc)
            else:
                log.exception("live id worker failed")
            self.error = f"worker failed ({type(exc).__name__}: {exc})"
            self.status = f"live id: stopped ({type(exc).__name__})"
        finally:
            close = getattr(self.ident, "close", None)
            if close is not None:
                close()

    def _loop(self) -> None:
        while True:
            self._wake.wait(0.05)
            self._wake.clear()
            stopping = self._stop.is_set()
            queued = self._queued  # read before taking: what is handled after this pass
            self._take()
            done = self._advance(stopping=stopping)
            if done or stopping:
                if self.ident.n_samples >= self.ident.min_samples:
                    self._count_missed()  # due times the worker was too busy for
                    self._update(final=True)
                self._handled = queued
                return
            self._maybe_update()
            self._handled = queued

    def _take(self) -> None:
        while self._inbox:
            self._grid.take(*self._inbox.popleft())

    def _advance(self, *, stopping: bool) -> bool:
        """Append the grid samples every stream now covers; True once the window has closed
        and every row inside it has arrived."""
        held, complete = self._grid.advance(n_done=self.ident.n_samples, stopping=stopping)
        if held is not None:
            m = len(self.inputs)
            self.ident.append(u=held[:, :m], y=held[:, m:])
        return complete

    def _count_missed(self) -> None:
        """Count the update times that came due before the final update and got none."""
        (start, stop), latest = self._grid.window, self._grid.latest
        if self._next_due is None or start is None:
            return
        end = latest if stop is None else min(latest, stop)
        if end > self._next_due:
            self.skipped += int((end - self._next_due) // self.config.update_period)

    def _maybe_update(self) -> None:
        (start, stop), latest = self._grid.window, self._grid.latest
        if start is not None and not self.updates and not self.failed:
            n, need = self.ident.n_samples, self.ident.min_samples
            if stop is not None:  # ended (an abort, or a short excitation) before an update
                self.status = (f"live id: the excitation ended after {n}/{need} samples, "
                               "too few for an update" if n < need else
                               "live id: the excitation ended; final update")
            else:
                self.status = (f"live id: excitation on, {n}/{need} samples for the first "
                               "update" if n < need else "live id: first update running")
        if start is None or stop is not None or self.ident.n_samples < self.ident.min_samples:
            return
        period = self.config.update_period
        if self._next_due is None:  # the first due time with enough samples
            self._next_due = start + period * np.ceil((latest - start) / period)
        if latest < self._next_due:
            return
        missed = int((latest - self._next_due) // period)
        self.skipped += missed
        self._next_due += (missed + 1) * period
        self._update(final=False)

    def _update(self, *, final: bool) -> None:
        t, t0 = self._grid.latest, time.perf_counter()
        try:
            k = max(2, round(self.fit_window_s / self.dt))
            upd = self.ident.update(fit_samples=k)
            yc, y_pred = upd.recent.measured, upd.recent.predicted
            fit, nvar = finite_mean(upd.recent.fit_pct), upd.recent.innovation_nvar
        except Exception as exc:  # a constant channel, a numerical failure: counted
            self.failed += 1
            self.error = f"update failed ({type(exc).__name__}: {exc})"
            self.status = f"live id: {self.updates} updates; last failed: {exc}"
            log.log(logging.WARNING if self.failed == 1 else logging.DEBUG, "live id %s",
                    self.error)
            return
        poles = sorted_poles(upd.poles)
        move = pole_move(poles, self._history[-1][1]) if self._history else float("nan")
        self._history.append((t, poles))
        new = max(1, min(k, upd.n_samples - self._last_n))
        self._last_n = upd.n_samples
        elapsed = time.perf_counter() - t0
        n, c = upd.n_samples, self.config
        fw_end = self._grid.g0 + (n - 1) * self.dt
        fw_times = fw_end - self.dt * np.arange(new)[::-1]
        offset = self._grid.offset
        self.updates += 1
        row = (t, fw_end, upd.span_s, n, c.order, c.past, c.future, fit, nvar, move,
               float(np.abs(poles).max()), elapsed, self.skipped, int(final))
        self._outbox.append(row + tuple(x for p in poles for x in (p.real, p.imag)))
        info = Update(t=t, n_samples=n, span_s=upd.span_s, order=c.order, poles=poles,
                      singular_values=upd.singular_values, fit_pct=fit, innovation_nvar=nvar,
                      pole_move=move, update_s=elapsed, skipped=self.skipped, final=final,
                      fw_times=fw_times, host_times=fw_times + offset,
                      measured=yc[-new:], predicted=y_pred[-new:])
        moved = "first" if np.isnan(move) else f"{move:.1e}"  # no earlier poles to move from
        self.status = (f"live id {self.updates} upd ({self.skipped} skipped)  n {c.order}  "
                       f"max|p| {row[10]:.3f}  move {moved}  "
                       f"innov {nvar:.3f}  fit {fit:.0f}%")
        if final:
            self.final, self.final_model = info, upd.model
        elif self.convergence is not None and self.converged_at is None:
            reason = converged(self.convergence, self._history, t=t, poles=poles)
            if reason:
                self.converged_at, self._end_reason = round(t, 3), reason
        for obs in list(self.observers):
            self._notify(obs, "update", update=info)

    def _notify(self, obs: Any, method: str, **kw: Any) -> None:
        try:
            getattr(obs, method)(**kw)
        except Exception:
            log.exception("live id observer %s.%s failed; dropped", type(obs).__name__, method)
            if obs in self.observers:
                self.observers.remove(obs)
