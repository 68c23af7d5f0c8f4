"""Identified discrete-time state-space models in innovation form.

.. math::

    x(k+1) = A x(k) + B u(k) + K e(k), \\qquad y(k) = C x(k) + D u(k) + e(k)

with ``A (n, n)``, ``B (n, m)``, ``C (l, n)``, ``D (l, m)``, ``K (n, l)``, sample period ``dt``
seconds, ``e`` white with covariance ``noise_cov (l, l)``. Matrices are in the physical units
of the channels (any scaling used during identification is already undone). An identified
model's ``noise_cov`` is the covariance :math:`\\frac1N \\sum_t e e^T` of its own one-step
prediction errors :math:`e(t) = y(t) - \\hat y(t|t-1)` on the identification data
(:mod:`sysid.innovation_cov`): the innovation covariance that goes with its K (for K = 0, the
simulation-error covariance). Files: HDF5
(``.h5``/``.hdf5``), JSON (``.json``) and MATLAB (``.mat``) via :meth:`StateSpaceModel.save`
and :func:`load_model`.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from sysid.errors import DimensionError, MissingDependencyError, ModelFileError

__all__ = ["FORMAT", "FORMAT_VERSION", "StateSpaceModel", "load_model"]

log = logging.getLogger(__name__)

FORMAT = "sysid.StateSpaceModel"
FORMAT_VERSION = 1
_MATRICES = ("A", "B", "C", "D", "K")


def _matrix(name: str, value: object, shape: tuple[int, int], dims: str) -> np.ndarray:
    arr = np.array(value, dtype=float, copy=True)
    if arr.ndim == 1 and shape[1] == 1 and arr.shape[0] == shape[0]:
        arr = arr[:, None]
    if arr.ndim == 0 and shape == (1, 1):
        arr = arr.reshape(1, 1)
    if arr.shape != shape:
        raise DimensionError(f"{name} has shape {arr.shape}; it must be {dims} = {shape}")
    if not np.all(np.isfinite(arr)):
        raise DimensionError(f"{name} contains NaN or inf; pass finite values")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class StateSpaceModel:
    """A discrete-time innovation-form model (see the module docstring).

    ``D`` and ``K`` default to zeros. ``noise_cov`` ``(l, l)`` (None if unknown) is the
    innovation covariance; an identified model's is that of its own one-step prediction errors
    on the identification data (:mod:`sysid.innovation_cov`), MATLAB's ``NoiseVariance`` of an
    ``idss``. ``provenance`` records how the model was made (method, horizons, order, data,
    software version); ``scaling`` the per-channel scales used inside the identification
    (informative only: the matrices are already in physical units).
    """

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray | None = None
    K: np.ndarray | None = None
    dt: float = 1.0
    input_names: tuple[str, ...] | None = None
    output_names: tuple[str, ...] | None = None
    input_units: tuple[str, ...] | None = None
    output_units: tuple[str, ...] | None = None
    noise_cov: np.ndarray | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = object.__setattr__
        a = np.atleast_2d(np.asarray(self.A, dtype=float))
        n = a.shape[0]
        set_(self, "A", _matrix("A", a, (n, n), "(n, n)"))
        b = np.asarray(self.B, dtype=float)
        m = b.shape[1] if b.ndim == 2 else 1
        set_(self, "B", _matrix("B", b, (n, m), "(n, m)"))
        c = np.atleast_2d(np.asarray(self.C, dtype=float))
        ell = c.shape[0]
        set_(self, "C", _matrix("C", c, (ell, n), "(l, n)"))
        set_(self, "D", _matrix("D", np.zeros((ell, m)) if self.D is None else self.D,
                                (ell, m), "(l, m)"))
        set_(self, "K", _matrix("K", np.zeros((n, ell)) if self.K is None else self.K,
                                (n, ell), "(n, l)"))
        if self.noise_cov is not None:
            set_(self, "noise_cov", _matrix("noise_cov", self.noise_cov, (ell, ell), "(l, l)"))
        dt = float(self.dt)
        if not np.isfinite(dt) or dt <= 0:
            raise DimensionError(f"dt is {self.dt}; pass the sample period in seconds (> 0)")
        set_(self, "dt", dt)
        for attr, count, default in (("input_names", m, "u"), ("output_names", ell, "y"),
                                     ("input_units", m, None), ("output_units", ell, None)):
            given = getattr(self, attr)
            if given is None:
                given = [f"{default}{i}" for i in range(count)] if default else [""] * count
            labels = tuple(str(s) for s in given)
            if len(labels) != count:
                raise DimensionError(f"{attr} has {len(labels)} entries; give {count}")
            set_(self, attr, labels)
        set_(self, "provenance", dict(self.provenance))

    # ---- structure -------------------------------------------------------------------------
    @property
    def n_states(self) -> int:
        """Model order n."""
        return int(self.A.shape[0])

    @property
    def n_inputs(self) -> int:
        """Number of inputs m."""
        return int(self.B.shape[1])

    @property
    def n_outputs(self) -> int:
        """Number of outputs l."""
        return int(self.C.shape[0])

    def poles(self) -> np.ndarray:
        """Eigenvalues of A, ``(n,)`` complex (discrete time)."""
        return np.linalg.eigvals(self.A)

    @property
    def is_stable(self) -> bool:
        """All poles strictly inside the unit circle."""
        return bool(self.n_states == 0 or np.max(np.abs(self.poles())) < 1.0)

    def predictor_poles(self) -> np.ndarray:
        """Eigenvalues of the one-step predictor matrix ``A - K C``, ``(n,)``."""
        return np.linalg.eigvals(self.A - self.K @ self.C)

    @property
    def predictor_is_stable(self) -> bool:
        """``A - K C`` has all eigenvalues strictly inside the unit circle."""
        return bool(self.n_states == 0 or np.max(np.abs(self.predictor_poles())) < 1.0)

    def replace(self, **changes: Any) -> StateSpaceModel:
        """A copy with some fields changed (e.g. ``model.replace(K=new_K)``)."""
        return dataclasses.replace(self, **changes)

    # ---- simulation ------------------------------------------------------------------------
    def simulate(self, u: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        """Deterministic response ``y (N, l)`` to inputs ``u (N, m)`` from state ``x0 (n,)``.

        ``x(k+1) = A x(k) + B u(k)``, ``y(k) = C x(k) + D u(k)``; ``x0`` defaults to zero.
        An unstable model's response may overflow: its samples are then ``inf`` or ``nan``
        (what callers read as diverged), without numpy's overflow warnings.
        """
        u = np.asarray(u, dtype=float)
        if u.ndim == 1 and self.n_inputs == 1:
            u = u[:, None]
        if u.ndim != 2 or u.shape[1] != self.n_inputs:
            raise DimensionError(f"u has shape {u.shape}; the model needs (N, {self.n_inputs})")
        x = np.zeros(self.n_states) if x0 is None else np.asarray(x0, dtype=float).reshape(-1)
        if x.shape != (self.n_states,):
            raise DimensionError(f"x0 has {x.size} entries; the model has {self.n_states} states")
        states = np.empty((u.shape[0], self.n_states))
        bu = u @ self.B.T
        a_t = np.ascontiguousarray(self.A.T)
        with np.errstate(over="ignore", invalid="ignore"):
            for k in range(u.shape[0]):
                states[k] = x
                x = x @ a_t + bu[k]
            return states @ self.C.T + u @ self.D.T

    # ---- export ----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-able dict (lists of floats), with format name and version."""
        out: dict[str, Any] = {"format": FORMAT, "version": FORMAT_VERSION,
                               "dt": self.dt, "dt_unit": "s"}
        for name in _MATRICES:
            out[name] = getattr(self, name).tolist()
        out["noise_cov"] = None if self.noise_cov is None else self.noise_cov.tolist()
        for attr in ("input_names", "output_names", "input_units", "output_units"):
            out[attr] = list(getattr(self, attr))
        out["provenance"] = _jsonable(self.provenance)
        return out

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> StateSpaceModel:
        """Inverse of :meth:`to_dict`."""
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            got = d.get("format") if isinstance(d, dict) else type(d).__name__
            raise ModelFileError(f"not a sysid model (format {got!r}, expected {FORMAT!r}); "
                                 "pass a dict made by StateSpaceModel.to_dict")
        if int(d.get("version", 0)) > FORMAT_VERSION:
            raise ModelFileError(f"model format version {d['version']} is newer than "
                                 f"{FORMAT_VERSION}; upgrade sysid to read it")
        keys = (*_MATRICES, "dt", "input_names", "output_names", "input_units", "output_units",
                "noise_cov", "provenance")
        missing = [k for k in keys if k not in d]
        if missing:
            raise ModelFileError(f"sysid model dict lacks {', '.join(missing)}; pass a dict "
                                 "made by StateSpaceModel.to_dict")
        kwargs = {k: d[k] for k in keys}
        return cls(**kwargs)

    def to_json(self) -> str:
        """The model as a JSON string (see :meth:`to_dict`)."""
        return json.dumps(self.to_dict(), indent=1)

    def to_control(self) -> Any:
        """A python-control ``StateSpace`` (discrete, ``dt`` seconds) of ``(A, B, C, D)``.

        python-control allows no ``.`` in signal names, so session channel names such as
        ``motor.m1`` become ``motor_m1`` (and a name repeated after that gets ``_2``, ...).
        """
        try:
            import control
        except ImportError as exc:
            raise MissingDependencyError(
                "to_control needs python-control; install it with `pip install control`"
            ) from exc
        return control.ss(self.A, self.B, self.C, self.D, self.dt,
                          inputs=_control_names(self.input_names),
                          outputs=_control_names(self.output_names))

    def save(self, path: str | Path) -> Path:
        """Write the model; the suffix picks the format: ``.h5``/``.hdf5``, ``.json``, ``.mat``."""
        from sysid import model_io

        return model_io.save(self, Path(path))


def _control_names(names: tuple[str, ...]) -> list[str]:
    """Signal names python-control accepts: ``.`` (and other non-identifier characters)
    replaced by ``_``, duplicates made unique."""
    out: list[str] = []
    for name in names:
        base = re.sub(r"\W", "_", name) or "signal"
        cand, i = base, 2
        while cand in out:
            cand, i = f"{base}_{i}", i + 1
        out.append(cand)
    return out


def load_model(path: str | Path) -> StateSpaceModel:
    """Read a model written by :meth:`StateSpaceModel.save` (HDF5, JSON or MAT)."""
    from sysid import model_io

    return model_io.load(Path(path))


def _jsonable(obj: Any) -> Any:
    """Provenance values made JSON-able (numpy scalars/arrays to Python numbers/lists)."""
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    return obj
