"""The result of :func:`sysid.compare`: per-channel fit percent plus the signals behind it."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

__all__ = ["CompareResult"]


@dataclass(frozen=True, eq=False)
class CompareResult(np.lib.mixins.NDArrayOperatorsMixin):
    """Outcome of :func:`sysid.compare`: the per-channel fit, with what produced it.

    It behaves as the fit array ``(l,)`` wherever an array is expected: ``np.asarray(r)``,
    ``r[0]``, ``len(r)``, iteration, arithmetic and comparisons (``r >= 95``) all act on
    ``r.fit``; the attributes below carry the rest.

    ``fit`` (l,) percent over all experiments together; ``fits`` (E, l) per experiment;
    ``y_model`` / ``y_measured`` one (N_e, l) array per experiment; ``x0`` one (W_e, n) array
    of initial states per experiment (W_e windows); ``horizon`` steps (None: simulation);
    ``window`` samples (None: whole record); stability flags of the model (eig A) and of its
    predictor (eig A - KC); ``diverged`` when the model output is not finite.
    """

    fit: np.ndarray
    fits: np.ndarray
    y_model: tuple[np.ndarray, ...]
    y_measured: tuple[np.ndarray, ...]
    x0: tuple[np.ndarray, ...]
    horizon: int | None
    window: int | None
    model_stable: bool
    predictor_stable: bool
    diverged: bool
    output_names: tuple[str, ...]

    @property
    def mode(self) -> str:
        """``"simulation"``, ``"windowed simulation"`` or ``"k-step prediction"``."""
        if self.horizon is not None:
            return f"{self.horizon}-step prediction"
        return "simulation" if self.window is None else "windowed simulation"

    def summary(self) -> str:
        """One line per output channel: name and fit in percent, then the flags."""
        lines = [f"{self.mode}:"]
        lines += [f"  {n}: {f:7.2f} %" for n, f in zip(self.output_names, self.fit, strict=True)]
        if not self.model_stable:
            lines.append("  model is unstable (max |eig A| >= 1)")
        if not self.predictor_stable:
            lines.append("  predictor A - KC is unstable: use sysid.stable_predictor(model)")
        if self.diverged:
            lines.append("  model output diverged (non-finite)")
        return "\n".join(lines)

    def __array__(self, dtype: object = None, copy: bool | None = None) -> np.ndarray:
        return np.array(self.fit, dtype=dtype, copy=True if copy is None else copy)

    def __array_ufunc__(self, ufunc: np.ufunc, method: str, *inputs: object, **kwargs: object):
        args = [np.asarray(x.fit) if isinstance(x, CompareResult) else x for x in inputs]
        return getattr(ufunc, method)(*args, **kwargs)

    def __len__(self) -> int:
        return len(self.fit)

    def __getitem__(self, index: object) -> np.ndarray:
        return np.asarray(self.fit)[index]

    def __iter__(self) -> Iterator[np.floating]:
        return iter(np.asarray(self.fit))
