r"""How many past samples the data's one-step predictor needs: the lag of the best VARX model.

The past horizon of a subspace method must cover the memory of the predictor,
:math:`(A - K C)^p \approx 0` (thesis section 3.3; Chiuso's PBSID), and that memory is in
samples, not seconds: a thermal process logged every 2 s and a quadrotor's rate loop logged at
50 Hz both forget in a few tens of samples. It is measured as MATLAB's ``n4sid`` chooses its
horizons (``N4Horizon="auto"``): by an information criterion over high-order ARX models.

For each lag :math:`L = 0 \dots L_{max}` the VARX model

.. math::

    y(k) = D u(k) + \sum_{i=1}^{L} \left[ A_i y(k-i) + B_i u(k-i) \right] + e(k)

is fitted by least squares on the same samples (each flight from its sample :math:`L_{max}`
on) and scored by the small-sample Akaike criterion for multivariate regression (Hurvich and
Tsai, 1993):

.. math::

    \mathrm{AICc}(L) = N \log\det\hat\Sigma_L + N \ell \frac{N + q}{N - q - \ell - 1},
    \qquad q = m + L (m + \ell),

with :math:`N` rows, :math:`\hat\Sigma_L = E^T E / N` ``(l, l)`` the residual covariance.
One QR factor of ``[regressors | outputs]`` ordered by lag gives every :math:`\hat\Sigma_L`
(the rows below column ``q`` of the outputs' block). Channels are scaled to unit variance
first (the criterion does not change; the factor is better conditioned), one scale for all
flights; each flight's mean is removed (an offset would otherwise be explained by long lags).
Directions of :math:`\hat\Sigma_L` below the factor's numerical precision (outputs that the
regressors explain exactly) count at that precision, so :math:`\log\det` stays finite and
the search goes on while other directions still gain; it stops when every output is
explained exactly (noise-free data: the observability index, one lag more for the means
removed in place of an intercept).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from sysid.data import IOData

__all__ = ["MAX_LAG", "ROWS_PER_REGRESSOR", "Memory", "predictor_memory"]

#: Longest lag tried: a rate far above the dynamics is better resampled (``zoh_resample``).
MAX_LAG = 50
#: Rows of the regression per regressor of one output equation that the longest lag keeps.
ROWS_PER_REGRESSOR = 5
#: Rows stacked per QR step (bounds the memory used on long records).
_CHUNK = 20_000
#: Residual singular values below this times the factor's size and norm count as zero
#: (machine precision with numpy's ``matrix_rank`` margin): explained exactly.
_EXACT_TOL = np.finfo(float).eps


@dataclass(frozen=True, eq=False)
class Memory:
    """Result of :func:`predictor_memory`: ``lag`` the chosen :math:`L` (samples),
    ``aicc`` ``(max_lag + 1,)`` the criterion for ``L = 0..max_lag``, ``n_rows`` the rows
    each lag was fitted on, ``capped`` whether the chosen lag is the longest one tried."""

    lag: int
    aicc: np.ndarray
    max_lag: int
    n_rows: int

    @property
    def capped(self) -> bool:
        return self.lag == self.max_lag


def _longest_lag(flights: Sequence[IOData], *, limit: int) -> int:
    m, c = flights[0].n_inputs, flights[0].n_inputs + flights[0].n_outputs
    best = 0
    for lag in range(1, limit + 1):
        rows = sum(max(d.n_samples - lag, 0) for d in flights)
        if rows < ROWS_PER_REGRESSOR * (m + lag * c) + flights[0].n_outputs + 2:
            break
        best = lag
    return best


def _pooled(flights: Sequence[IOData]) -> tuple[list[np.ndarray], list[np.ndarray],
                                                np.ndarray, np.ndarray]:
    """Each flight's inputs and outputs less their own means (one intercept a flight), and
    which input and output channels move at all (pooled standard deviation > 0)."""
    us = [d.u - d.u.mean(axis=0) for d in flights]
    ys = [d.y - d.y.mean(axis=0) for d in flights]
    su = np.sqrt(sum((u ** 2).sum(axis=0) for u in us) / sum(len(u) for u in us))
    sy = np.sqrt(sum((y ** 2).sum(axis=0) for y in ys) / sum(len(y) for y in ys))
    # one scale for every flight (the pooled model's coefficients must hold in all of them);
    # a constant channel is left out (a dead output makes every determinant zero)
    us = [u[:, su > 0] / su[su > 0] for u in us]
    ys = [y[:, sy > 0] / sy[sy > 0] for y in ys]
    return us, ys, su > 0, sy > 0


def predictor_memory(flights: Sequence[IOData], *, max_lag: int = MAX_LAG) -> Memory:
    """The VARX lag with the smallest AICc (module docstring) over ``0..max_lag``, fewer when
    the records are short (at least :data:`ROWS_PER_REGRESSOR` rows a regressor). Each
    flight's mean is removed (an intercept a flight); channels are scaled by one pooled
    standard deviation; constant channels are left out."""
    top = _longest_lag(flights, limit=max_lag)
    used = [d for d in flights if d.n_samples > top]
    empty = Memory(lag=0, aicc=np.full(top + 1, np.inf), max_lag=top, n_rows=0)
    if not used:
        return empty
    us, ys, live_u, live_y = _pooled(used)
    m, ell = int(live_u.sum()), int(live_y.sum())
    if ell == 0:
        return empty
    r: np.ndarray | None = None
    n_rows = 0
    for u, y in zip(us, ys, strict=True):
        n = len(y)
        z = np.hstack([y, u])
        for start in range(top, n, _CHUNK):
            stop = min(start + _CHUNK, n)
            block = np.hstack([u[start:stop]]
                              + [z[start - i:stop - i] for i in range(1, top + 1)]
                              + [y[start:stop]])
            stack = block if r is None else np.vstack([r, block])
            r = scipy.linalg.qr(stack, mode="r", check_finite=False)[0][:block.shape[1]]
            n_rows += stop - start
    aicc = np.full(top + 1, np.inf)
    if r is None:
        return Memory(lag=0, aicc=aicc, max_lag=top, n_rows=0)
    width = r.shape[1]
    if r.shape[0] < width:
        r = np.vstack([r, np.zeros((width - r.shape[0], width))])
    # residual directions below the factor's numerical rank tolerance are explained exactly:
    # each counts at that floor, so the determinant stays finite and keeps falling while
    # other directions still gain from longer lags (noise-free data of more states than
    # outputs, an output that is an exact filter of the inputs beside noisy ones)
    floor = (_EXACT_TOL * width * float(np.linalg.norm(r, 2))) ** 2 / n_rows
    for lag in range(top + 1):
        q = m + lag * (m + ell)
        if n_rows - q - ell - 1 <= 0:
            break
        var = scipy.linalg.svdvals(r[q:, width - ell:], check_finite=False) ** 2 / n_rows
        var = np.concatenate([var, np.zeros(ell - var.size)])
        logdet = float(np.sum(np.log(np.maximum(var, floor))))
        aicc[lag] = n_rows * logdet + n_rows * ell * (n_rows + q) / (n_rows - q - ell - 1)
        if np.all(var <= floor):  # every output explained exactly: no memory beyond this lag
            break
    return Memory(lag=int(np.argmin(aicc)), aicc=aicc, max_lag=top, n_rows=n_rows)
