"""Input-output data sets (:class:`IOData`) and their block Hankel views.

Arrays are ``(n_samples, n_channels)``: ``u`` is ``(N, m)``, ``y`` is ``(N, l)``, sampled
uniformly every ``dt`` seconds. Several experiments (flights) are a list of ``IOData``; they are
never joined end to end: each contributes its own Hankel columns (see :func:`block_hankel`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from sysid.errors import DataError, DimensionError

__all__ = [
    "IOData",
    "as_flights",
    "block_hankel",
    "check_excited",
    "hankel_columns",
]

log = logging.getLogger(__name__)


def _as_2d(name: str, x: object) -> np.ndarray:
    """Float copy of ``x`` as ``(N, c)``: a 1-D array becomes one column."""
    arr = np.array(x, dtype=float, copy=True)
    if arr.ndim == 1:
        arr = arr[:, None]
    if arr.ndim != 2:
        raise DimensionError(
            f"{name} has {arr.ndim} dimensions; pass a (n_samples, n_channels) array"
        )
    return arr


def _check_finite(name: str, arr: np.ndarray, labels: Sequence[str]) -> None:
    bad = ~np.isfinite(arr)
    if bad.any():
        k, c = np.argwhere(bad)[0]
        raise DataError(
            f"{name} channel {c} ({labels[c]!r}) is {arr[k, c]} at sample {k} "
            f"(and {int(bad.sum()) - 1} more); remove or interpolate non-finite samples"
        )


def _labels(kind: str, given: Sequence[str] | None, count: int, default: str) -> tuple[str, ...]:
    if given is None:
        return tuple(f"{default}{i}" for i in range(count))
    labels = tuple(str(s) for s in given)
    if len(labels) != count:
        raise DimensionError(f"{kind} has {len(labels)} entries for {count} channels; "
                             f"give exactly {count}")
    return labels


@dataclass(frozen=True, eq=False)
class IOData:
    """One uniformly sampled experiment.

    Attributes:
        u: inputs, ``(N, m)`` (a 1-D array is promoted to one column).
        y: outputs, ``(N, l)``.
        dt: sample period in seconds.
        input_names, output_names: channel labels (default ``u0..``, ``y0..``).
        input_units, output_units: channel units (default ``""``, i.e. unknown).

    The arrays are read-only copies; every value is checked finite (the error names channel
    and sample).
    """

    u: np.ndarray
    y: np.ndarray
    dt: float
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    input_units: tuple[str, ...] | None = None
    output_units: tuple[str, ...] | None = None
    source: str = field(default="")

    def __post_init__(self) -> None:
        u = _as_2d("u", self.u)
        y = _as_2d("y", self.y)
        if u.shape[0] != y.shape[0]:
            raise DimensionError(
                f"u has {u.shape[0]} samples but y has {y.shape[0]}; trim both to the same length"
            )
        dt = float(self.dt)
        if not np.isfinite(dt) or dt <= 0:
            raise DataError(f"dt is {self.dt}; pass the sample period in seconds (> 0)")
        m, ell = u.shape[1], y.shape[1]
        set_ = object.__setattr__
        set_(self, "input_names", _labels("input_names", self.input_names, m, "u"))
        set_(self, "output_names", _labels("output_names", self.output_names, ell, "y"))
        set_(self, "input_units", _labels("input_units", self.input_units, m, "") if
             self.input_units is not None else ("",) * m)
        set_(self, "output_units", _labels("output_units", self.output_units, ell, "") if
             self.output_units is not None else ("",) * ell)
        _check_finite("u", u, self.input_names)
        _check_finite("y", y, self.output_names)
        u.setflags(write=False)
        y.setflags(write=False)
        set_(self, "u", u)
        set_(self, "y", y)
        set_(self, "dt", dt)

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.u.shape[0])

    @property
    def n_inputs(self) -> int:
        """Number of input channels m."""
        return int(self.u.shape[1])

    @property
    def n_outputs(self) -> int:
        """Number of output channels l."""
        return int(self.y.shape[1])

    @property
    def time(self) -> np.ndarray:
        """Sample times in seconds, ``(N,)``, starting at 0."""
        return np.arange(self.n_samples) * self.dt

    @property
    def w(self) -> np.ndarray:
        """Joint signal ``w(k) = [u(k); y(k)]`` as ``(N, m + l)``."""
        return np.hstack([self.u, self.y])


def as_flights(data: IOData | Sequence[IOData]) -> tuple[IOData, ...]:
    """Normalise one ``IOData`` or a list of them to a tuple of consistent flights.

    All flights must have the same channel counts and sample period (relative 1e-9).
    """
    flights = (data,) if isinstance(data, IOData) else tuple(data)
    if not flights:
        raise DataError("no data given; pass an IOData or a non-empty list of IOData")
    for i, d in enumerate(flights):
        if not isinstance(d, IOData):
            raise DataError(f"data[{i}] is a {type(d).__name__}; wrap arrays in sysid.IOData")
    ref = flights[0]
    for i, d in enumerate(flights[1:], start=1):
        if (d.n_inputs, d.n_outputs) != (ref.n_inputs, ref.n_outputs):
            raise DimensionError(
                f"data[{i}] has {d.n_inputs} inputs/{d.n_outputs} outputs but data[0] has "
                f"{ref.n_inputs}/{ref.n_outputs}; give every flight the same channels"
            )
        if abs(d.dt - ref.dt) > 1e-9 * ref.dt:
            raise DataError(f"data[{i}] has dt={d.dt} s but data[0] has dt={ref.dt} s; "
                            "resample every flight to the same rate")
    return flights


def hankel_columns(n_samples: int, *, block_rows: int) -> int:
    """Columns of a block Hankel matrix with ``block_rows`` block rows: ``N - rows + 1``."""
    return max(n_samples - block_rows + 1, 0)


def block_hankel(x: np.ndarray, *, block_rows: int, start: int = 0) -> np.ndarray:
    """Block Hankel matrix of the signal ``x`` ``(N, c)``.

    Returns ``H`` of shape ``(block_rows * c, M)`` with ``M = N - start - block_rows + 1`` and
    ``H[i*c:(i+1)*c, j] = x[start + i + j]``: block row ``i`` is the signal delayed by ``i``.
    A copy (contiguous), since the products downstream want it so.
    """
    x = np.asarray(x, dtype=float)
    n, c = x.shape
    cols = hankel_columns(n - start, block_rows=block_rows)
    win = np.lib.stride_tricks.sliding_window_view(x[start:start + cols + block_rows - 1],
                                                   block_rows, axis=0)  # (M, c, rows)
    return np.ascontiguousarray(win.transpose(2, 1, 0).reshape(block_rows * c, cols))


def check_excited(flights: Sequence[IOData], *, rel_tol: float = 1e-12) -> tuple[
        np.ndarray, np.ndarray]:
    """Per-channel standard deviation of inputs and outputs over all flights.

    Returns ``(u_std (m,), y_std (l,))`` in the channels' units; raises :class:`DataError`
    naming the first channel that is constant within every flight: its standard deviation in
    the flight is at most ``rel_tol`` times the larger of its mean magnitude and the largest
    standard deviation of any channel in that flight. The second reference catches what is left
    of a constant channel after linear detrending (rounding noise around zero). A channel
    constant within each flight makes its delayed copies in the data matrix identical, however
    the constants differ between flights.
    """
    ref = flights[0]
    labels = [("input", c, ref.input_names[c]) for c in range(ref.n_inputs)] + [
        ("output", c, ref.output_names[c]) for c in range(ref.n_outputs)]
    constant = np.ones(len(labels), dtype=bool)
    spread = np.zeros(len(labels))
    for d in flights:
        arr = np.hstack([d.u, d.y])
        std = arr.std(axis=0)
        floor = rel_tol * np.maximum(np.abs(arr).mean(axis=0), std.max())
        constant &= std <= np.maximum(floor, 1e-300)
        spread = np.maximum(spread, std)
    for j in np.flatnonzero(constant)[:1]:
        kind, c, name = labels[j]
        where = "in every flight" if len(flights) > 1 else ""
        raise DataError(f"{kind} channel {c} ({name!r}) is constant{' ' + where if where else ''}"
                        f" (std {spread[j]:.3g}); drop it or excite it before identifying")
    u = np.vstack([d.u for d in flights])
    y = np.vstack([d.y for d in flights])
    return u.std(axis=0), y.std(axis=0)
