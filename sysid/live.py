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

No threads here: the ground station's listener (``groundstation/flight/liveid.py``) calls
:meth:`append` and :meth:`update` from its own worker.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from sysid.data import IOData
from sysid.errors import DataError, DimensionError
from sysid.factor import DataProducts, check_horizons, min_samples
from sysid.finish import Focus, check_focus
from sysid.iem import iem
from sysid.model import StateSpaceModel
from sysid.realize import check_order
from sysid.stability import Stability, check_stability

__all__ = ["LiveIdentifier", "LiveUpdate"]

log = logging.getLogger(__name__)


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
        if np.any(std <= 1e-12 * max(float(std.max()), 1e-300)):
            raise DataError("a channel is constant so far; excite it (or wait)")
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

    def update(self) -> LiveUpdate:
        """Identify a model from all samples so far with the offline IEM on these products."""
        t0 = time.perf_counter()
        prod = self.products()
        model = iem(None, order=self.order, past=self.past, future=self.future,  # type: ignore[arg-type]
                    feedthrough=self.feedthrough, focus=self.focus, stability=self.stability,
                    products=prod)
        poles = model.poles()
        sv = np.asarray(model.provenance.get("singular_values", []), dtype=float)
        return LiveUpdate(n_samples=self._n, span_s=self._n * self.dt, order=self.order,
                          past=self.past, future=self.future, poles=poles,
                          singular_values=sv, model=model,
                          elapsed_s=time.perf_counter() - t0)
