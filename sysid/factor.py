"""The data products of subspace identification, built in one pass over the samples.

Every method here works on the joint block Hankel matrix of the (scaled) signal
``w(k) = [u(k); y(k)]`` (``c = m + l`` channels) with ``B = p + f`` block rows:

.. math::

    W = \\begin{bmatrix} Z_p \\\\ W_f \\end{bmatrix}, \\quad
    W[t c + i, j] = w_i(j + t), \\quad t = 0..B-1, \\; j = 0..M-1, \\; M = N - B + 1

so block rows ``0..p-1`` are the past ``Z_p`` (thesis eq. 3.23, in time order) and block rows
``p..p+f-1`` the future ``U_f, Y_f`` (eq. 3.19). Several flights each contribute their own
columns (never joined end to end).

Only the Gram matrix :math:`G = W W^T` (``(Bc, Bc)``) is formed. Because W is block Hankel,
block ``(a, b)``, ``d = b - a >= 0``, is a lag-``d`` correlation minus a few edge terms:

.. math::

    G_{ab} = \\sum_{t=0}^{N-1-d} w(t) w(t+d)^T - \\sum_{t<a} w(t) w(t+d)^T
             - \\sum_{t \\ge a+M}^{N-1-d} w(t) w(t+d)^T

which costs :math:`O(N B c^2)` instead of :math:`O(N B^2 c^2)` for ``W @ W.T``. Any ordering of
the rows (e.g. ``[Z_p; y_0; u_0; y_1; ...]`` for IEM, ``[U_f; Z_p; Y_f]`` for PO-MOESP,
eq. 3.16) is a symmetric permutation of G; its Cholesky factor ``L`` is the ``L`` of the LQ
factorization ``W_perm = L Q^T`` (``Q`` orthonormal, never formed). If G is too ill conditioned
for Cholesky (estimated ``cond(W) > 1e6``) the factor comes from a QR of ``W_perm^T`` instead.

**Noise-free data.** With n states W has rank ``(p + f) m + n``: each output row beyond the
state's reach is a function of the rows before it. Such rows (distance from the span of the
earlier rows at most :data:`DEPENDENT_TOL` of their norm, judged on the QR factor of the data)
get a zero diagonal and a zero column, and the methods' regressions (:func:`solve_right`) give
them coefficient zero: exact for deterministic data, and nothing changes for noisy data, which
has no such rows. What is not the deterministic case is refused in one line: channels
dependent at lag 0 (:func:`sysid.data.check_independent`) and inputs that are not persistently
exciting.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg

from sysid.data import IOData, as_flights, block_hankel, check_excited, hankel_columns
from sysid.errors import DataError, HorizonError, ParameterError

__all__ = ["DataProducts", "build_products", "check_exciting", "given_products", "grid_values",
           "min_samples", "solve_right", "triangular_factor"]

log = logging.getLogger(__name__)

#: Largest estimated cond(W) accepted from the Cholesky route before falling back to QR.
COND_LIMIT = 1e6
#: A row of W closer than this (relative to its norm) to the span of the rows before it is
#: taken as dependent on them: noise-free simulations leave ~1e-12, noise of 1e-10 is kept.
DEPENDENT_TOL = 1e-10
#: Smallest eigenvalue, relative to the largest, of the Gram of the input rows alone below
#: which the inputs are not persistently exciting (exact dependence leaves ~1e-16).
INPUT_RANK_TOL = 1e-13


def min_samples(*, past: int, future: int, n_channels: int, n_flights: int = 1) -> int:
    """Fewest samples per flight for a full-rank ``W``: ``M >= B c`` columns overall."""
    blocks = past + future
    rows = blocks * n_channels
    per_flight_cols = -(-rows // n_flights)
    return per_flight_cols + blocks - 1


@dataclass(frozen=True, eq=False)
class DataProducts:
    """Gram matrix of the scaled joint Hankel matrix and what is needed to interpret it.

    Attributes:
        gram: ``(B c, B c)`` with ``B = past + future``, ``c = m + l``; canonical row order.
        past, future: horizons p and f (samples).
        n_inputs, n_outputs: m and l.
        n_columns: total Hankel columns M over all flights.
        u_scale, y_scale: ``(m,)``, ``(l,)`` channel scales (the data were divided by them).
        flights: the data (kept for the QR fallback).
        cache: factors a caller already has for these products, keyed by method (e.g.
            ``("iem", feedthrough)``: the IEM-ordered LQ factor and its Γ_f L_p), so a horizon
            grid (:mod:`sysid.grid`) shares one factorization among its pairs.
    """

    gram: np.ndarray
    past: int
    future: int
    n_inputs: int
    n_outputs: int
    n_columns: int
    u_scale: np.ndarray
    y_scale: np.ndarray
    flights: tuple[IOData, ...]
    cache: dict[Any, Any] = field(default_factory=dict, repr=False)

    @property
    def n_channels(self) -> int:
        """c = m + l."""
        return self.n_inputs + self.n_outputs

    def rows(self, *, block: int, kind: str) -> np.ndarray:
        """Canonical row indices of ``u`` (kind "u") or ``y`` (kind "y") at block row ``block``."""
        base = block * self.n_channels
        if kind == "u":
            return np.arange(base, base + self.n_inputs)
        return np.arange(base + self.n_inputs, base + self.n_channels)

    def scaled_w(self, flight: IOData) -> np.ndarray:
        """``(N, c)`` joint signal of one flight divided by the channel scales."""
        return np.hstack([flight.u / self.u_scale, flight.y / self.y_scale])


def _gram_one(w: np.ndarray, blocks: int) -> np.ndarray:
    """Gram matrix of ``block_hankel(w, block_rows=blocks)`` by lag correlations (see module)."""
    n, c = w.shape
    g = np.empty((blocks * c, blocks * c))
    for d in range(blocks):
        full = w[: n - d].T @ w[d:]
        na = blocks - d  # block rows a = 0..na-1 with b = a + d
        head = np.zeros((na, c, c))
        tail = np.zeros((na, c, c))
        if na > 1:
            head[1:] = np.cumsum(np.einsum("ti,tj->tij", w[: na - 1], w[d:d + na - 1]), axis=0)
            t0 = n - d - (na - 1)
            tp = np.einsum("ti,tj->tij", w[t0:n - d], w[t0 + d:n])
            tail[1:] = np.cumsum(tp[::-1], axis=0)
        blk = full[None] - head - tail[::-1]
        for a in range(na):
            b = a + d
            g[a * c:(a + 1) * c, b * c:(b + 1) * c] = blk[a]
            g[b * c:(b + 1) * c, a * c:(a + 1) * c] = blk[a].T
    return g


def check_horizons(*, past: int, future: int) -> None:
    """Raise :class:`HorizonError` unless ``past >= 1`` and ``future >= 2`` are integers."""
    for name, value, low in (("past", past, 1), ("future", future, 2)):
        if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
            raise HorizonError(f"{name}={value!r}; pass an integer horizon >= {low} (samples)")


def grid_values(name: str, values: Iterable[object], *, low: int) -> list[int]:
    """``values`` (pasts, futures or orders of a grid) as ints; :class:`ParameterError` naming
    ``name`` and the first that is not an integer >= ``low`` (``4.5``, ``0``, ``True``)."""
    out = list(values)
    for v in out:
        if isinstance(v, bool) or not isinstance(v, int | np.integer) or v < low:
            raise ParameterError(f"{name} holds {v!r}; pass integers >= {low}")
    return [int(v) for v in out]


def _warn_if_offset(flights: Sequence[IOData], *, u_std: np.ndarray, y_std: np.ndarray,
                    ratio: float = 3.0) -> None:
    """Subspace methods identify deviations from an operating point: a channel whose mean is
    several standard deviations away from zero (hover thrust in PWM, 1 g on acc.z) biases the
    model badly. Warn, naming the channels (``load_session`` detrends by default)."""
    names = [*flights[0].input_names, *flights[0].output_names]
    std = np.concatenate([u_std, y_std])
    mean = np.mean([np.concatenate([d.u.mean(axis=0), d.y.mean(axis=0)]) for d in flights],
                   axis=0)
    off = [f"{n} (mean {mu:.3g}, std {sd:.3g})" for n, mu, sd in zip(names, mean, std,
                                                                     strict=True)
           if abs(mu) > ratio * sd]
    if off:
        _warn_once(f"channels far from zero mean: {', '.join(off)}; identify deviations from "
                   "the operating point: detrend first (sysid.detrend_data, or "
                   "load_session(detrend='mean'))")


_WARNED: dict[str, None] = {}


def _warn_once(message: str) -> None:
    """``log.warning(message)`` unless the last warnings (up to 64) said it already: a
    selection builds the products of the same data several times (held-out split, refit)."""
    if message in _WARNED:
        return
    _WARNED[message] = None
    while len(_WARNED) > 64:
        del _WARNED[next(iter(_WARNED))]
    log.warning("%s", message)


def build_products(data: IOData | Sequence[IOData], *, past: int, future: int,
                   scale: bool = True) -> DataProducts:
    """Validate the data and build the Gram matrix of the joint Hankel matrix, one pass.

    With ``scale`` each channel is divided by its standard deviation over all flights, so the
    factorization is well balanced whatever the units (PWM counts vs g vs deg/s).
    """
    check_horizons(past=past, future=future)
    flights = as_flights(data)
    m, ell = flights[0].n_inputs, flights[0].n_outputs
    blocks = past + future
    rows = blocks * (m + ell)
    cols = sum(hankel_columns(d.n_samples, block_rows=blocks) for d in flights)
    if cols < rows:
        need = min_samples(past=past, future=future, n_channels=m + ell,
                           n_flights=len(flights))
        have = min(d.n_samples for d in flights)
        hint = (f" (u and y are (n_samples, n_channels): {m + ell} channels for {have} samples "
                "looks transposed)" if have < m + ell else "")
        raise DataError(
            f"{have} samples{' per flight' if len(flights) > 1 else ''} are too few for "
            f"past={past}, future={future} with {m + ell} channels; need at least {need} "
            f"samples per flight (or shorter horizons){hint}"
        )
    short = [i for i, d in enumerate(flights) if hankel_columns(d.n_samples, block_rows=blocks) < 1]
    if short:
        log.warning("flight(s) %s shorter than past + future = %d samples contribute nothing",
                    short, blocks)
    u_std, y_std = check_excited(flights)
    _warn_if_offset(flights, u_std=u_std, y_std=y_std)
    u_scale = u_std if scale else np.ones(m)
    y_scale = y_std if scale else np.ones(ell)
    gram = np.zeros((rows, rows))
    products = DataProducts(gram=gram, past=past, future=future, n_inputs=m, n_outputs=ell,
                            n_columns=cols, u_scale=u_scale, y_scale=y_scale, flights=flights)
    for d in flights:
        if hankel_columns(d.n_samples, block_rows=blocks) > 0:
            gram += _gram_one(products.scaled_w(d), blocks)
    log.debug("Gram %dx%d from %d columns of %d flight(s)", rows, rows, cols, len(flights))
    return products


def given_products(data: IOData | Sequence[IOData], *, products: DataProducts | None,
                   past: int, future: int, scale: bool) -> DataProducts:
    """``products`` when given (checked against the horizons), else :func:`build_products`."""
    if products is None:
        return build_products(data, past=past, future=future, scale=scale)
    if (products.past, products.future) != (past, future):
        raise HorizonError(f"products were built for past={products.past}, "
                           f"future={products.future}, not past={past}, future={future}; "
                           "build them for these horizons")
    return products


def _qr_factor(products: DataProducts, order: np.ndarray) -> np.ndarray:
    """Lower-triangular ``L`` with ``W_perm = L Q^T``, from a QR of ``W_perm^T`` (slow path)."""
    blocks = products.past + products.future
    w_t = np.hstack([block_hankel(products.scaled_w(d), block_rows=blocks)[order]
                     for d in products.flights
                     if hankel_columns(d.n_samples, block_rows=blocks) > 0]).T
    r = scipy.linalg.qr(w_t, mode="r", overwrite_a=True, check_finite=False)[0]
    r = r[: len(order)]
    signs = np.where(np.diag(r) < 0, -1.0, 1.0)
    return (signs[:, None] * r).T


def solve_right(tri: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """``Theta`` with ``Theta @ tri = rhs`` for a lower-triangular factor ``tri`` ``(s, s)``.

    Rows of a factor from :func:`triangular_factor` that depend on earlier rows (deterministic
    data) have a zero diagonal and a zero column: they add nothing to the span, so their
    coefficients are set to zero and the rest solved exactly (a basic least-squares solution,
    exact for noise-free data). Without such rows this is one triangular solve."""
    keep = np.diag(tri) != 0.0
    if keep.all():
        return scipy.linalg.solve_triangular(tri, rhs.T, lower=True, trans="T",
                                             check_finite=False).T
    theta = np.zeros((rhs.shape[0], tri.shape[0]))
    theta[:, keep] = scipy.linalg.solve_triangular(tri[np.ix_(keep, keep)], rhs[:, keep].T,
                                                   lower=True, trans="T",
                                                   check_finite=False).T
    return theta


def _check_inputs_exciting(products: DataProducts) -> None:
    """Raise :class:`DataError` when the input rows of the Hankel matrix alone are dependent
    (not persistently exciting over ``past + future`` samples): then dependent rows are a lack
    of excitation, not the deterministic dynamics that :func:`triangular_factor` handles."""
    blocks, c, m = products.past + products.future, products.n_channels, products.n_inputs
    names = products.flights[0].input_names
    for channels in [[j] for j in range(m)] + ([list(range(m))] if m > 1 else []):
        rows = np.concatenate([np.asarray(channels) + b * c for b in range(blocks)])
        ev = np.linalg.eigvalsh(products.gram[np.ix_(rows, rows)])
        if ev[0] <= INPUT_RANK_TOL * ev[-1]:
            which = (f"input channel {channels[0]} ({names[channels[0]]!r}) is" if
                     len(channels) == 1 else "the inputs together are")
            raise DataError(f"{which} not persistently exciting over past + future = {blocks} "
                            "samples (the delayed copies are linearly dependent: a delayed copy "
                            "of another input, noise-free feedback without a reference, or too "
                            "few frequencies); excite more or shorten the horizons")


def check_exciting(products: DataProducts) -> None:
    """Refuse inputs that are not persistently exciting over ``past + future`` samples, judged
    as :func:`triangular_factor` judges the whole data matrix (its dependent rows, then
    :func:`_check_inputs_exciting`), on the input rows of every block alone: for a method that
    never factors all the rows (PARSIM-K factors the past and the first future sample only, so
    a single sinusoid, exciting over two samples, gave a confident order-2 model where IEM and
    PO-MOESP refuse). Once per products."""
    if "inputs-exciting" in products.cache:
        return
    c, m = products.n_channels, products.n_inputs
    rows = np.concatenate([np.arange(m) + b * c for b in range(products.past + products.future)])
    triangular_factor(products, rows)  # a DataError if those rows are dependent
    products.cache["inputs-exciting"] = True


def _drop_dependent(low: np.ndarray, dependent: np.ndarray) -> np.ndarray:
    """``L`` re-triangularised without the rows ``dependent``: each of those rows lies in the
    span of the rows before it, so it gets no basis direction of its own (a zero diagonal and
    a zero column) and keeps its coordinates in the others'; what is left of it (below
    :data:`DEPENDENT_TOL` of its norm) is dropped. ``W_perm = L Q^T`` still holds to that
    tolerance, with ``Q`` orthonormal on the kept columns."""
    keep = ~dependent
    q2, r2 = scipy.linalg.qr(low[keep].T, mode="economic", check_finite=False)
    q2 = q2 * np.where(np.diag(r2) < 0, -1.0, 1.0)
    out = np.zeros_like(low)
    out[:, keep] = low @ q2
    return np.tril(out)


def triangular_factor(products: DataProducts, order: np.ndarray, *,
                      method: str = "auto") -> np.ndarray:
    """``L`` (lower triangular, ``(r, r)``) of the LQ factorization of the rows ``order`` of W.

    ``method``: "cholesky" (Gram route), "qr" (explicit Hankel matrix, O(N r^2)), or "auto"
    (Cholesky, falling back to QR when the estimated ``cond(W)`` exceeds :data:`COND_LIMIT`).

    Noise-free data are rank deficient in a known way: with ``n`` states, ``Y_p`` and ``Y_f``
    are functions of the inputs and the state, so ``W`` has rank ``(p + f) m + n``, not
    ``(p + f)(m + l)``. A row (of the QR route) whose distance from the span of the rows before
    it is at most :data:`DEPENDENT_TOL` of its norm then gets a zero diagonal and a zero column
    (:func:`_drop_dependent`), and the methods solve their regressions with
    :func:`solve_right`, which is exact for such data. Channels dependent at lag 0 (duplicated
    channels, an input copying an output) are refused before (:func:`sysid.data.check_excited`),
    and inputs that are not persistently exciting are refused here.
    """
    if method not in ("auto", "cholesky", "qr"):
        raise ValueError(f"factorization={method!r}; use 'auto', 'cholesky' or 'qr'")
    if method != "qr":
        g = products.gram[np.ix_(order, order)]
        try:
            low = np.linalg.cholesky(g)
            diag = np.abs(np.diag(low))
            cond = diag.max() / diag.min() if diag.min() > 0 else np.inf
        except np.linalg.LinAlgError:
            low, cond = None, np.inf
        if low is not None and (cond < COND_LIMIT or method == "cholesky"):
            return low
        log.info("Gram matrix ill conditioned (cond(W) ~ %.2g); using QR of the data", cond)
    low = _qr_factor(products, order)
    dependent = np.abs(np.diag(low)) <= DEPENDENT_TOL * np.linalg.norm(low, axis=1)
    if dependent.any():
        _check_inputs_exciting(products)
        log.info("%d of %d rows of the data matrix depend on earlier ones (noise-free data: "
                 "outputs determined by the inputs and the state); solved as deterministic",
                 int(dependent.sum()), dependent.size)
        low = _drop_dependent(low, dependent)
    return low
