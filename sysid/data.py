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
    "check_independent",
    "check_magnitudes",
    "hankel_columns",
]

log = logging.getLogger(__name__)


def _as_2d(name: str, x: object) -> np.ndarray:
    """Float copy of ``x`` as ``(N, c)``: a 1-D array becomes one column. Complex, ragged or
    non-numeric values are a :class:`DataError` (numpy raised a bare ValueError or TypeError,
    and dropped a complex array's imaginary part with a warning)."""
    try:
        raw = np.asarray(x)  # ragged: a ValueError
        if raw.dtype.kind == "c" or (raw.dtype.kind == "O" and any(
                isinstance(v, complex) for v in raw.ravel())):
            raise TypeError("complex values")
        if raw.dtype.kind in "US" or (raw.dtype.kind == "O" and any(
                isinstance(v, str | bytes) for v in raw.ravel())):
            raise TypeError("text, not numbers")  # numpy would read "1.5" as 1.5
        arr = np.array(raw, dtype=float, copy=True)
    except (TypeError, ValueError) as exc:
        raise DataError(f"{name} is not an array of real numbers ({exc}); pass a "
                        "(n_samples, n_channels) array of floats") from None
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
        try:
            dt = float(self.dt)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            dt = np.nan
        if isinstance(self.dt, bool | np.bool_ | str | bytes) or not np.isfinite(dt) or dt <= 0:
            shown = repr(self.dt) if isinstance(self.dt, str | bytes) else self.dt
            raise DataError(f"dt is {shown}; pass the sample period in seconds (> 0)")
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

    All flights must have the same channel counts and sample period (relative 1e-9), and
    values whose sums of squares float64 holds (:func:`check_magnitudes`).
    """
    if isinstance(data, IOData):
        flights: tuple[IOData, ...] = (data,)
    elif isinstance(data, Sequence) and not isinstance(data, str | bytes):
        flights = tuple(data)
    else:
        raise DataError(f"data is a {type(data).__name__}; pass an IOData or a list of IOData")
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
            raise DataError(f"data[{i}]{_from(d)} has dt={d.dt} s but data[0]{_from(ref)} has "
                            f"dt={ref.dt} s; resample every flight to the same rate (sessions "
                            "read together by sysid.session_io.load_sessions share one)")
    check_magnitudes(flights)
    return flights


def _from(d: IOData) -> str:
    """`` (from SOURCE)`` for a flight that says where it comes from, else ``""``."""
    return f" (from {d.source})" if d.source else ""


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


#: A channel is constant when its standard deviation is at most this times its mean magnitude.
CONSTANT_TOL = 1e-12
#: A channel is a linear combination of the channels before it (at the same sample) when its
#: distance from their span is at most this times its norm.
DEPENDENT_TOL = 1e-10
#: Room the sums of squares of an identification need beyond one sum of squares of a
#: channel (products of Hankel rows, Gram matrices): a channel whose largest magnitude
#: exceeds sqrt(float max / (samples * HEADROOM)), or lies below sqrt(float tiny *
#: HEADROOM) (about 1e-151), is refused (:func:`check_magnitudes`).
HEADROOM = 1e6


def _rounding_residue(x: np.ndarray) -> bool:
    """Whether ``x`` ``(N,)`` looks like what detrending leaves of a constant: a few values
    (at most 16), all small integer multiples of a power of two (exact float differences of
    numbers close to the constant). A 0/1 switching input looks the same, so this alone
    refuses nothing (see :func:`check_excited`)."""
    values = np.unique(x)
    if values.size < 2 or values.size > 16:
        return False
    step = float(np.min(np.diff(values)))
    ratio = values / step
    return (np.frexp(step)[0] == 0.5 and bool(np.all(ratio == np.round(ratio)))
            and float(np.ptp(ratio)) <= 16.0)


def _constant(arr: np.ndarray, *, rel_tol: float) -> np.ndarray:
    """Per column of ``arr`` ``(N, c)``: constant within this flight (:func:`check_excited`)."""
    std = arr.std(axis=0)
    flat = std <= rel_tol * np.abs(arr.mean(axis=0))
    others = np.array([np.max(np.delete(std, j), initial=0.0) for j in range(std.size)])
    residue = np.array([std[j] <= rel_tol * others[j] and _rounding_residue(arr[:, j])
                        for j in range(std.size)], dtype=bool)
    return flat | residue


def check_magnitudes(flights: Sequence[IOData], *, headroom: float = HEADROOM) -> None:
    r"""Raise :class:`sysid.errors.DataError`, in one line naming the channel, when a channel's
    values would overflow the sums of squares an identification forms (largest magnitude
    above :math:`\sqrt{f_{max} / (N h)}`, :math:`N` the samples of all the records, :math:`h`
    = ``headroom``) or underflow them (all magnitudes below :math:`\sqrt{f_{tiny} h}`, none
    zero), :math:`f` float64's limits. The remedy is another unit.

    Parameters
    ----------
    flights : records of one system (checked: :func:`as_flights`), each ``u`` (N, m),
        ``y`` (N, l).
    headroom : room beyond one sum of squares (:data:`HEADROOM`).
    """
    recs = list(flights)
    n = sum(d.n_samples for d in recs)
    fmax, tiny = np.finfo(float).max, np.finfo(float).tiny
    high, low = np.sqrt(fmax / (max(n, 1) * headroom)), np.sqrt(tiny * headroom)
    ref = recs[0]
    labels = _channel_labels(ref)
    peaks = np.array([np.abs(d.w).max(axis=0, initial=0.0) for d in recs])
    peak = peaks.max(axis=0)
    for j, label in enumerate(labels):
        if peak[j] > high:
            e = int(np.argmax(peaks[:, j]))
            k = int(np.argmax(np.abs(recs[e].w[:, j])))
            where = f"sample {k}" + (f" of record {e + 1}" if len(recs) > 1 else "")
            raise DataError(f"{label} reaches {recs[e].w[k, j]:.3g} at {where}: beyond "
                            f"{high:.3g} the sums of squares of {n} samples overflow; rescale "
                            f"it (another unit) before identifying")
        if 0.0 < peak[j] < low:
            raise DataError(f"{label} is at most {peak[j]:.3g} in magnitude: below {low:.3g} "
                            f"its squares underflow; rescale it (another unit) before "
                            f"identifying")


def check_excited(flights: Sequence[IOData], *, rel_tol: float = CONSTANT_TOL) -> tuple[
        np.ndarray, np.ndarray]:
    """Per-channel standard deviation of inputs and outputs over all flights.

    Returns ``(u_std (m,), y_std (l,))`` in the channels' units; raises :class:`DataError`
    naming the first channel that is constant within every flight, then the first channel
    that is a linear combination of the others at every sample (:func:`check_independent`).

    Constancy is decided per channel on its own scale, so the units of the other channels
    never change the verdict: a channel is constant when its standard deviation is at most
    ``rel_tol`` times its mean magnitude (exactly zero included). The one exception is what
    linear detrending leaves of a constant: rounding noise around zero, a handful of values
    that are multiples of a power of two. On its own it looks like a 0/1 switching signal, so
    it counts as constant only when its spread is also below ``rel_tol`` of another channel's.
    A channel constant within each flight makes its delayed copies in the data matrix
    identical, however the constants differ between flights.
    """
    ref = flights[0]
    labels = _channel_labels(ref)
    constant = np.ones(len(labels), dtype=bool)
    spread = np.zeros(len(labels))
    for d in flights:
        if not d.n_samples:  # nothing to judge (a held-out part of a record too short to split)
            continue
        arr = np.hstack([d.u, d.y])
        constant &= _constant(arr, rel_tol=rel_tol)
        spread = np.maximum(spread, arr.std(axis=0))
    for j in np.flatnonzero(constant)[:1]:
        where = "in every flight" if len(flights) > 1 else ""
        raise DataError(f"{labels[j]} is constant{' ' + where if where else ''}"
                        f" (std {spread[j]:.3g}); drop it or excite it before identifying")
    u = np.vstack([d.u for d in flights])
    y = np.vstack([d.y for d in flights])
    u_std, y_std = u.std(axis=0), y.std(axis=0)
    # each flight's mean removed first: an output that is an input plus an offset (y = -3 u + 2)
    # is as dependent once detrended, and the constant hid it (a -390 % model, silently)
    check_independent(np.vstack([w - w.mean(axis=0) for w in (np.hstack([d.u, d.y])
                                                             for d in flights) if len(w)]),
                      labels=labels)
    return u_std, y_std


def _channel_labels(ref: IOData) -> list[str]:
    return [f"input channel {c} ({ref.input_names[c]!r})" for c in range(ref.n_inputs)] + [
        f"output channel {c} ({ref.output_names[c]!r})" for c in range(ref.n_outputs)]


def check_independent(w: np.ndarray, *, labels: Sequence[str]) -> None:
    """Raise :class:`DataError` naming a channel of ``w`` ``(N, c)`` (all flights' samples,
    inputs then outputs, each flight's mean removed by the caller) that is a linear
    combination of the channels before it at every sample: a duplicated channel, an input
    copying an output, an output that is a multiple of another. That is structural rank
    deficiency, which no identification resolves; the dependence of outputs on past inputs
    and outputs (noise-free data) is not (see :func:`sysid.factor.triangular_factor`)."""
    if w.shape[0] < w.shape[1]:
        return  # too few samples for any identification; the callers say so
    rms = np.sqrt(np.mean(w * w, axis=0))
    r = np.linalg.qr(w / rms, mode="r")
    norms = np.sqrt(w.shape[0])
    dep = np.flatnonzero(np.abs(np.diag(r)) <= DEPENDENT_TOL * norms)
    if dep.size:
        j = int(dep[0])
        coef = np.linalg.lstsq(r[:j, :j], r[:j, j], rcond=None)[0] / rms[:j] * rms[j]
        used = [labels[i] for i in np.flatnonzero(np.abs(coef) > 1e-8 * np.abs(coef).max())] \
            if j else []
        of = ", ".join(used) if used else "the channels before it"
        raise DataError(f"{labels[j]} is a linear combination of {of} at every sample, "
                        "each flight's mean aside (the "
                        "data are rank deficient: duplicated or linearly dependent channels); "
                        "drop redundant channels")
