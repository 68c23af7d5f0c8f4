"""One factorization for a whole grid of (past, future) horizons on one data set.

For pasts up to :math:`p_{max}` and futures up to :math:`f_{max}` the joint Hankel matrix is
built (as its Gram matrix, :mod:`sysid.factor`) once, with :math:`B = p_{max} + f_{max}` block
rows over the common columns :math:`M = N - B + 1`. A pair ``(p, f)`` is its time-aligned
sub-block: past blocks :math:`p_{max}-p \\dots p_{max}-1`, future blocks
:math:`p_{max} \\dots p_{max}+f-1`, which is exactly the Hankel matrix of the trimmed data
``data[p_max - p : N - (f_max - f)]`` (:func:`pair_flights`). So every pair sees the same M
columns, and each pair's model equals ``iem(pair_flights(...), ...)`` built on its own.

**Scaling.** Identification divides each channel by its standard deviation over the data it
is given (:func:`sysid.factor.build_products`); the trimmed data of each pair has its own. The
Gram matrix is formed on the data divided by the full data's deviations ``s0`` (so it is well
balanced), and a pair rescales it by the diagonal ``D = s0 / s_pair``:
:math:`G_{pair} = D G D`, whose Cholesky factor is :math:`D L` (D > 0).

**IEM shares one factor per past.** With IEM's row order ``[Z_p; y_0; u_0; y_1; ...]`` the rows
of ``(p, f)`` are the leading rows of those of ``(p, f_max)``, so its factor is the leading
block :math:`D L_{:r,:r}` of the one for ``(p, f_max)``. Row i of :math:`\\widehat{\\Gamma_f L_p}`
is a regression of future row i on the rows before it (:mod:`sysid.iem`), which does not
depend on f: the ``(p, f)`` estimate is the first ``f l`` rows of the ``(p, f_max)`` one, and
scales as :math:`\\theta' = D_i \\theta D_s^{-1}`. Each pair then needs one SVD (per order).
PO-MOESP's order ``[U_f; Z_p; Y_f]`` is not nested in f: it factors the pair's Gram itself.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData, as_flights, check_excited, hankel_columns
from sysid.errors import DataError, SysIdError
from sysid.factor import DataProducts, _gram_one, check_horizons, min_samples
from sysid.iem import iem_order, iem_signals

__all__ = ["HorizonGrid", "build_grid", "pair_flights"]

log = logging.getLogger(__name__)


def _trim(d: IOData, start: int, stop: int) -> IOData:
    return dataclasses.replace(d, u=d.u[start:stop], y=d.y[start:stop])


def pair_flights(flights: Sequence[IOData], *, past: int, future: int, past_max: int,
                 future_max: int) -> tuple[IOData, ...]:
    """The data a pair ``(past, future)`` of the grid sees: each flight without its first
    ``past_max - past`` and last ``future_max - future`` samples."""
    return tuple(_trim(d, past_max - past, d.n_samples - (future_max - future))
                 for d in flights)


@dataclass(frozen=True, eq=False)
class HorizonGrid:
    """The Gram matrix of the largest Hankel matrix of a grid (module docstring).

    ``gram`` ``(B c, B c)``, ``B = past_max + future_max``, on the data divided by ``scale``
    (the full data's channel deviations, ``(c,)``); ``n_columns`` the common Hankel columns.
    """

    flights: tuple[IOData, ...]
    gram: np.ndarray
    scale: np.ndarray
    past_max: int
    future_max: int
    n_columns: int

    @property
    def n_inputs(self) -> int:
        return self.flights[0].n_inputs

    @property
    def n_outputs(self) -> int:
        return self.flights[0].n_outputs

    def flights_for(self, *, past: int, future: int) -> tuple[IOData, ...]:
        """:func:`pair_flights` of this grid."""
        return pair_flights(self.flights, past=past, future=future, past_max=self.past_max,
                            future_max=self.future_max)

    def products(self, *, past: int, future: int, scale: np.ndarray | None = None
                 ) -> DataProducts:
        """Data products of the pair, equal to ``build_products(flights_for(...))``: the
        sub-block of the Gram matrix rescaled to the pair's channel deviations (or to
        ``scale``, ``(c,)``, e.g. the grid's own for the shared IEM factor)."""
        check_horizons(past=past, future=future)
        if past > self.past_max or future > self.future_max:
            raise DataError(f"pair ({past}, {future}) is outside the grid "
                            f"(pasts <= {self.past_max}, futures <= {self.future_max})")
        flights = self.flights_for(past=past, future=future)
        if scale is None:
            u_std, y_std = check_excited(flights)
            scale = np.concatenate([u_std, y_std])
        c = scale.size
        ratio = np.tile(self.scale / scale, past + future)
        off = (self.past_max - past) * c
        rows = slice(off, off + (past + future) * c)
        gram = ratio[:, None] * self.gram[rows, rows] * ratio[None, :]
        m = self.n_inputs
        return DataProducts(gram=gram, past=past, future=future, n_inputs=m,
                            n_outputs=self.n_outputs, n_columns=self.n_columns,
                            u_scale=scale[:m], y_scale=scale[m:], flights=flights)

    def iem_products(self, *, past: int, futures: Sequence[int], feedthrough: bool
                     ) -> dict[int, DataProducts]:
        """Products of the pairs ``(past, f)`` for every f in ``futures``, sharing one IEM
        factor: that of ``(past, max(futures))``, computed here (module docstring)."""
        f_top = max(futures)
        top = self.products(past=past, future=f_top, scale=self.scale)
        iem_signals(top, feedthrough=feedthrough)  # fills top.cache
        low, gamma_lp = top.cache[("iem", bool(feedthrough))]
        order = iem_order(top, feedthrough=feedthrough)
        c, ell = self.scale.size, self.n_outputs
        pc = past * c
        out = {}
        for f in futures:
            pair = self.products(past=past, future=f)
            d = np.concatenate([pair.u_scale, pair.y_scale])
            ratio = (self.scale / d)[order[: (past + f) * c] % c]  # D, per row of the factor
            r = ratio.size
            # rows of Γ_f L_p: the y channels of each future block; columns: the Z_p rows
            y_ratio = np.tile((self.scale / d)[self.n_inputs:], f)
            pair.cache[("iem", bool(feedthrough))] = (
                ratio[:, None] * low[:r, :r],
                y_ratio[:, None] * gamma_lp[: f * ell] / ratio[None, :pc])
            out[f] = pair
        return out


def build_grid(data: IOData | Sequence[IOData], *, past_max: int, future_max: int
               ) -> HorizonGrid:
    """The Gram matrix of the ``past_max + future_max`` block-row Hankel matrix of ``data``
    (each flight its own columns), on channels divided by their deviation over all data."""
    check_horizons(past=past_max, future=future_max)
    flights = as_flights(data)
    blocks = past_max + future_max
    c = flights[0].n_inputs + flights[0].n_outputs
    cols = sum(hankel_columns(d.n_samples, block_rows=blocks) for d in flights)
    if cols < blocks * c:
        need = min_samples(past=past_max, future=future_max, n_channels=c,
                           n_flights=len(flights))
        raise DataError(f"{min(d.n_samples for d in flights)} samples are too few for the "
                        f"largest pair past={past_max}, future={future_max} with {c} channels;"
                        f" need at least {need} samples per flight (or shorter horizons)")
    u_std, y_std = check_excited(flights)
    scale = np.concatenate([u_std, y_std])
    gram = np.zeros((blocks * c, blocks * c))
    for d in flights:
        if hankel_columns(d.n_samples, block_rows=blocks) > 0:
            gram += _gram_one(np.hstack([d.u, d.y]) / scale, blocks)
    log.debug("grid Gram %dx%d from %d columns", *gram.shape, cols)
    return HorizonGrid(flights=flights, gram=gram, scale=scale, past_max=past_max,
                       future_max=future_max, n_columns=cols)


def grid_products(grid: HorizonGrid, *, past: int, futures: Sequence[int], shared_iem: bool,
                  feedthrough: bool) -> dict[int, DataProducts | SysIdError]:
    """Products of every pair ``(past, f)``: sharing the IEM factor when ``shared_iem``, else
    each its own; a pair that cannot be built maps to its error."""
    if shared_iem:
        try:
            return dict(grid.iem_products(past=past, futures=futures, feedthrough=feedthrough))
        except SysIdError as exc:
            log.debug("shared factor for past %d failed (%s); pairs on their own", past, exc)
    out: dict[int, DataProducts | SysIdError] = {}
    for f in futures:
        try:
            out[f] = grid.products(past=past, future=f)
        except SysIdError as exc:
            out[f] = exc
    return out
