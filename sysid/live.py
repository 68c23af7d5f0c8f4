"""Live identification: the IEM data products kept up to date while samples arrive.

:class:`LiveIdentifier` takes rows of ``u`` and ``y`` on the identification grid as they come
(:meth:`LiveIdentifier.append`) and keeps the *raw* Gram matrix of the joint block Hankel
matrix (``B = p + f`` block rows, ``c = m + l`` channels) up to date, new columns only:

.. math::

    R \\mathrel{+}= W_{new} W_{new}^T \\qquad O(\\Delta (B c)^2)

together with per-channel running sums (a prefix sum of the samples). An update
(:meth:`LiveIdentifier.update`) turns the raw Gram into the Gram of the mean-removed, scaled
data exactly: with ``mu`` the channel means over the N samples, ``s_a`` the column sums of block
row ``a`` (``sum_{j<M} w(j + a)``) and ``M`` the number of columns,

.. math::

    G^c_{ab} = R_{ab} - s_a \\mu^T - \\mu s_b^T + M \\mu \\mu^T, \\qquad
    G = S^{-1} G^c S^{-1}

(``S`` the channel standard deviations repeated per block row), then hands
:class:`sysid.factor.DataProducts` built from it to :func:`sysid.iem.iem`: the same Cholesky
factor, ``iem_signals`` and ``realize_iem`` as offline identification, not a second algorithm.
The model of an update therefore equals ``sysid.iem`` of the same samples with their means
removed (``detrend_data(..., "mean")``) and the same settings, to rounding.

The samples are shifted by the mean of the first rows before they are accumulated (removing
the mean is invariant to a constant shift), so the raw Gram does not carry the operating point
(hover PWM, 1 g) and the centring loses no digits.

No threads here. The ground station's listener (``groundstation/flight/liveid.py``) drives
:class:`LiveIdentifierProcess` from its own worker thread: the same engine in a child
interpreter with one BLAS thread, so an update never holds the flight's interpreter lock (a thread
preempted while holding it delays the setpoint thread by a whole time slice on a busy host) and
no idle OpenBLAS thread spins on the cores the flight needs.
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any

import numpy as np
import threadpoolctl
from numpy.lib.stride_tricks import sliding_window_view

from sysid.data import IOData
from sysid.errors import DataError, DimensionError
from sysid.factor import DataProducts, check_horizons, min_samples
from sysid.finish import Focus, check_focus
from sysid.iem import iem
from sysid.model import StateSpaceModel
from sysid.realize import check_order
from sysid.stability import Stability, check_stability
from sysid.validate import fit_percent, predict

__all__ = ["LiveIdentifier", "LiveIdentifierProcess", "LiveUpdate", "RecentFit"]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class RecentFit:
    """The one-step-ahead prediction of the most recent samples by an update's model.

    Attributes:
        measured, predicted: ``(k, l)`` outputs (the mean of all samples removed) and their
            one-step predictions (:func:`sysid.validate.predict`, initial state estimated).
        fit_pct: ``(l,)`` NRMSE fit per output (:func:`sysid.validate.fit_percent`).
        innovation_nvar: one-step error variance over output variance, mean over outputs.
    """

    measured: np.ndarray
    predicted: np.ndarray
    fit_pct: np.ndarray
    innovation_nvar: float


@dataclass(frozen=True)
class LiveUpdate:
    """One live identification result.

    Attributes:
        n_samples: samples used (N). span_s: the data span in seconds (N dt).
        order, past, future: model order and horizons.
        poles: ``(order,)`` complex discrete-time poles of A.
        singular_values: the step-3 singular values (the order is chosen among them).
        model: the identified model (physical units, mean-removed data).
        elapsed_s: wall time of the update.
        recent: the one-step fit on the most recent samples (``update(fit_samples=k)``).
    """

    n_samples: int
    span_s: float
    order: int
    past: int
    future: int
    poles: np.ndarray
    singular_values: np.ndarray
    model: StateSpaceModel
    elapsed_s: float
    extra: dict[str, float] = field(default_factory=dict)
    recent: RecentFit | None = None


class LiveIdentifier:
    """Incremental Gram of the joint Hankel matrix and IEM models from it (module docstring).

    Args:
        n_inputs, n_outputs: m and l.
        order, past, future: IEM settings (as :func:`sysid.iem.iem`).
        dt: sample period of the grid (s).
        input_names, output_names, input_units, output_units: channel labels for the models.
        feedthrough, focus, stability: passed to :func:`sysid.iem.iem`.
        capacity: initial sample capacity (grown as needed).
    """

    def __init__(self, *, n_inputs: int, n_outputs: int, order: int, past: int, future: int,
                 dt: float, input_names: tuple[str, ...] | None = None,
                 output_names: tuple[str, ...] | None = None,
                 input_units: tuple[str, ...] | None = None,
                 output_units: tuple[str, ...] | None = None, feedthrough: bool = False,
                 focus: Focus = "prediction", stability: Stability = "auto",
                 capacity: int = 4096) -> None:
        check_horizons(past=past, future=future)
        check_order(order=order, past=past, future=future, n_inputs=n_inputs,
                    n_outputs=n_outputs)
        check_focus(focus)
        check_stability(stability)
        if not dt > 0:
            raise DataError(f"dt={dt!r}; the sample period must be positive (s)")
        self.m, self.ell = int(n_inputs), int(n_outputs)
        self.c = self.m + self.ell
        self.order, self.past, self.future = order, past, future
        self.blocks = past + future
        self.dt = float(dt)
        self.names = (input_names, output_names, input_units, output_units)
        self.feedthrough, self.focus, self.stability = feedthrough, focus, stability
        self._w = np.empty((max(capacity, self.blocks), self.c))
        self._n = 0
        self._ref: np.ndarray | None = None  # the constant shift (mean of the first rows)
        rows = self.blocks * self.c
        self._gram = np.zeros((rows, rows))  # raw Gram of the shifted samples
        self._cols = 0  # Hankel columns accumulated into _gram
        self._prefix_arr = np.zeros((self._w.shape[0] + 1, self.c))  # sum_{s<t} w(s)

    @property
    def n_samples(self) -> int:
        """Samples appended so far."""
        return self._n

    @property
    def min_samples(self) -> int:
        """Fewest samples for an update (a full-rank Hankel matrix)."""
        return min_samples(past=self.past, future=self.future, n_channels=self.c)

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        """The appended ``(u (N, m), y (N, l))`` in their units (copies)."""
        w = self._w[: self._n] + (self._ref if self._ref is not None else 0.0)
        return w[:, : self.m].copy(), w[:, self.m:].copy()

    def append(self, *, u: np.ndarray, y: np.ndarray) -> None:
        """Add rows ``u (k, m)``, ``y (k, l)`` (grid samples, in order) and their new columns."""
        u = np.atleast_2d(np.asarray(u, dtype=float))
        y = np.atleast_2d(np.asarray(y, dtype=float))
        if u.shape[1] != self.m or y.shape[1] != self.ell or u.shape[0] != y.shape[0]:
            raise DimensionError(f"append: u {u.shape} and y {y.shape}; expected (k, {self.m}) "
                                 f"and (k, {self.ell}) with the same k")
        w = np.hstack([u, y])
        if not np.all(np.isfinite(w)):
            raise DataError("append: non-finite sample (NaN or inf); resample first")
        k = w.shape[0]
        if k == 0:
            return
        if self._ref is None:
            self._ref = w.mean(axis=0)
        need = self._n + k
        if need > self._w.shape[0]:
            cap = max(need, 2 * self._w.shape[0])
            grown = np.empty((cap, self.c))
            grown[: self._n] = self._w[: self._n]
            self._w = grown
            prefix = np.zeros((cap + 1, self.c))
            prefix[: self._n + 1] = self._prefix_arr[: self._n + 1]
            self._prefix_arr = prefix
        self._w[self._n:need] = w - self._ref
        self._prefix_arr[self._n + 1:need + 1] = (self._prefix_arr[self._n]
                                                  + np.cumsum(self._w[self._n:need], axis=0))
        self._n = need
        cols = max(self._n - self.blocks + 1, 0)
        if cols > self._cols:
            # columns j = _cols..cols-1 are rows j..j+B-1 of w, flattened block by block
            win = sliding_window_view(self._w[self._cols:cols + self.blocks - 1],
                                      self.blocks, axis=0)  # (Δ, c, B)
            w_new = win.transpose(0, 2, 1).reshape(cols - self._cols, -1)
            self._gram += w_new.T @ w_new
            self._cols = cols

    def products(self) -> DataProducts:
        """The data products (centred, scaled Gram) of all samples so far, exactly."""
        n, cols, c, blocks = self._n, self._cols, self.c, self.blocks
        if n < self.min_samples:
            raise DataError(f"{n} samples are too few for past={self.past}, "
                            f"future={self.future} with {c} channels; need {self.min_samples}")
        w = self._w[:n]
        mu = self._prefix_arr[n] / n
        std = w.std(axis=0)
        flat = np.flatnonzero(std <= 1e-12 * max(float(std.max()), 1e-300))
        if flat.size:
            in_names, out_names = self.names[0], self.names[1]
            names = [*(in_names or [f"u{i}" for i in range(self.m)]),
                     *(out_names or [f"y{i}" for i in range(self.ell)])]
            shown = ", ".join(names[j] for j in flat[:4])
            more = f" and {flat.size - 4} more" if flat.size > 4 else ""
            raise DataError(f"constant so far: {shown}{more}; excite it, or wait (motors "
                            "constant at 0 are not running)")
        # s_a = sum_{j<M} w(j + a), from the running sums
        s = np.concatenate([self._prefix_arr[a + cols] - self._prefix_arr[a]
                            for a in range(blocks)])
        mu_b = np.tile(mu, blocks)
        gram = (self._gram - np.outer(s, mu_b) - np.outer(mu_b, s)
                + cols * np.outer(mu_b, mu_b))
        inv = 1.0 / np.tile(std, blocks)
        gram = gram * inv[:, None] * inv[None, :]
        centred = w - mu
        in_names, out_names, in_units, out_units = self.names
        flight = IOData(u=centred[:, : self.m], y=centred[:, self.m:], dt=self.dt,
                        input_names=in_names, output_names=out_names, input_units=in_units,
                        output_units=out_units, source="live")
        return DataProducts(gram=gram, past=self.past, future=self.future, n_inputs=self.m,
                            n_outputs=self.ell, n_columns=cols, u_scale=std[: self.m],
                            y_scale=std[self.m:], flights=(flight,))

    def update(self, *, fit_samples: int = 0) -> LiveUpdate:
        """Identify a model from all samples so far with the offline IEM on these products;
        with ``fit_samples``, also its one-step fit on that many most recent samples."""
        t0 = time.perf_counter()
        prod = self.products()
        model = iem(None, order=self.order, past=self.past, future=self.future,  # type: ignore[arg-type]
                    feedthrough=self.feedthrough, focus=self.focus, stability=self.stability,
                    products=prod)
        poles = model.poles()
        sv = np.asarray(model.provenance.get("singular_values", []), dtype=float)
        recent = self.recent_fit(model, samples=fit_samples) if fit_samples else None
        return LiveUpdate(n_samples=self._n, span_s=self._n * self.dt, order=self.order,
                          past=self.past, future=self.future, poles=poles,
                          singular_values=sv, model=model,
                          elapsed_s=time.perf_counter() - t0, recent=recent)

    def recent_fit(self, model: StateSpaceModel, *, samples: int) -> RecentFit:
        """``model``'s one-step prediction of the last ``samples`` samples (at least 2)."""
        n = self._n
        k = min(n, max(2, int(samples)))
        tail = self._w[n - k:n] - self._prefix_arr[n] / n  # the mean of all samples removed
        u, y = tail[:, : self.m], tail[:, self.m:]
        y_pred, _ = predict(model, u=u, y=y, horizon=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = (y - y_pred).var(axis=0) / y.var(axis=0)
        ratio = ratio[np.isfinite(ratio)]
        return RecentFit(measured=y, predicted=y_pred, fit_pct=fit_percent(y, y_pred),
                         innovation_nvar=float(ratio.mean()) if ratio.size else float("nan"))


class LiveIdentifierProcess:
    """A :class:`LiveIdentifier` in a child interpreter (one BLAS thread there).

    Same arguments and methods (``append``, ``update``, ``samples``, ``n_samples``,
    ``min_samples``) plus :meth:`close`. ``append`` returns at once (the rows go down a pipe);
    ``update`` and ``samples`` wait for the child while the calling thread holds no
    interpreter lock. The child runs at a lower CPU priority (:data:`CHILD_NICENESS`). An
    error in the child (bad rows, too few samples, a failed update) is raised again here by
    the next ``update`` or ``samples``; a child that died is an ``EOFError``. The settings
    are checked here first, so a bad one is the same one-line error as
    :class:`LiveIdentifier`'s.

    The child is ``python -c`` running :func:`_serve` on two pipes, not a
    :mod:`multiprocessing` child: those re-import the caller's main module, and a script
    that flies without an ``if __name__ == "__main__"`` guard would fly again.

    The parent decides when the child ends (:meth:`close`, or its pipe closing when the
    parent exits): :data:`PARENT_SIGNALS`, which a terminal sends to the whole process group
    (Ctrl-C, a hang-up) and the flight handles as an abort, are blocked in the child from its
    first instruction (a blocked signal stays blocked across ``exec``) and ignored by
    :func:`_serve`, so a Ctrl-C never ends an update half-way or prints the child's
    ``KeyboardInterrupt`` traceback, and the abort's final update still has its engine.
    """

    def __init__(self, **settings: Any) -> None:
        probe = LiveIdentifier(**{**settings, "capacity": 1})  # the settings' errors, here
        self.min_samples = probe.min_samples
        self._n = 0
        to_child, from_parent = os.pipe()
        to_parent, from_child = os.pipe()
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p)}
        code = ("import sys; from sysid.live import _serve; "
                "_serve(int(sys.argv[1]), int(sys.argv[2]))")
        try:
            with _parent_signals_blocked():  # the child starts with them blocked: module doc
                self._proc = subprocess.Popen(
                    [sys.executable, "-c", code, str(to_child), str(from_child)],
                    pass_fds=(to_child, from_child), stdin=subprocess.DEVNULL, env=env)
        finally:
            os.close(to_child)
            os.close(from_child)
        self._send = Connection(from_parent, readable=False)
        self._recv = Connection(to_parent, writable=False)
        self._send.send(settings)

    @property
    def n_samples(self) -> int:
        """Samples appended so far."""
        return self._n

    def append(self, *, u: np.ndarray, y: np.ndarray) -> None:
        u = np.atleast_2d(np.asarray(u, dtype=float))
        self._send.send(("append", u, np.atleast_2d(np.asarray(y, dtype=float))))
        self._n += u.shape[0]

    def update(self, *, fit_samples: int = 0) -> LiveUpdate:
        self._send.send(("update", fit_samples))
        return self._reply()

    def samples(self) -> tuple[np.ndarray, np.ndarray]:
        self._send.send(("samples", 0))
        return self._reply()

    def close(self, *, timeout_s: float = 5.0) -> None:
        """End the child (it also ends when this process does: its pipe closes)."""
        with contextlib.suppress(OSError):
            self._send.send(("close", 0))
        try:
            self._proc.wait(timeout_s)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            self._proc.wait()
        self._send.close()
        self._recv.close()

    def _reply(self) -> Any:
        kind, value = self._recv.recv()
        if kind == "error":
            raise value
        return value


#: How much lower the child's CPU priority is than its parent's (``nice``).
CHILD_NICENESS = 10

#: Signals the child of :class:`LiveIdentifierProcess` leaves to its parent.
PARENT_SIGNALS = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP")
                       if hasattr(signal, n))


@contextlib.contextmanager
def _parent_signals_blocked():
    """:data:`PARENT_SIGNALS` blocked in the calling thread (a child started meanwhile inherits
    the mask); one arriving meanwhile goes to another thread or waits, it is not lost."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, PARENT_SIGNALS)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _serve(commands_fd: int, replies_fd: int) -> None:
    """The child of :class:`LiveIdentifierProcess`: one identifier, commands from a pipe.

    It runs :data:`CHILD_NICENESS` steps nicer than the flight: on a busy host the ground
    station's threads and a real-time firmware in the loop get the CPU first, and an update
    that falls behind is skipped by the caller (it never holds the flight up). It leaves
    :data:`PARENT_SIGNALS` to the parent (ignored; blocked since it started) and ends quietly
    when the parent's end of a pipe closes. Its log stays off the flight's terminal (each
    update's warnings, such as a kept pole, printed there once per update): what matters
    comes back in the replies."""
    logging.getLogger().addHandler(logging.NullHandler())
    for sig in PARENT_SIGNALS:
        signal.signal(sig, signal.SIG_IGN)
    if hasattr(os, "nice"):
        os.nice(CHILD_NICENESS)
    threadpoolctl.threadpool_limits(limits=1)
    commands = Connection(commands_fd, writable=False)
    replies = Connection(replies_fd, readable=False)
    try:
        settings = commands.recv()
    except (EOFError, OSError):
        return
    live = LiveIdentifier(**settings)
    failed: Exception | None = None  # an append's error, raised by the next reply
    while True:
        try:
            command, *args = commands.recv()
        except (EOFError, OSError):
            return
        if command == "close":
            return
        if command == "append":
            if failed is None:
                try:
                    live.append(u=args[0], y=args[1])
                except Exception as exc:
                    failed = exc
            continue
        try:
            try:
                if failed is not None:
                    raise failed
                replies.send(("ok", live.update(fit_samples=args[0]) if command == "update"
                              else live.samples()))
            except Exception as exc:
                replies.send(("error", exc))
        except OSError:  # the parent is gone (its end of the pipe closed): nobody to answer
            return
