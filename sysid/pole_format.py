"""One way to describe the poles of a discrete-time model, as MATLAB's ``damp`` does.

Every pole table of the project (``sysid identify``, ``groundstation demo``, the pole panel of
the identification report) uses :func:`pole_rows` and :func:`pole_cells`, so the same model gives
the same numbers everywhere. For a pole :math:`z` sampled every :math:`\\Delta t`:

* :math:`s = \\ln z / \\Delta t` (the equivalent continuous-time pole),
* natural frequency :math:`f_n = |s| / 2\\pi` (Hz; a real pole has one too, e.g. a pole at
  :math:`z = 0.99` with :math:`\\Delta t = 0.02` s has :math:`f_n = 0.08` Hz),
* damping ratio :math:`\\zeta = -\\operatorname{Re} s / |s|` (1 for a real positive pole),
* time constant :math:`\\tau = -1 / \\operatorname{Re} s` (s; only for a stable pole).

Poles are sorted by decreasing modulus, then by imaginary part (a conjugate pair is adjacent,
the negative imaginary part first).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

__all__ = ["POLE_COLUMNS", "pole_cells", "pole_number", "pole_rows", "sorted_poles"]

POLE_COLUMNS = ("#", "pole", "|z|", "angle [deg]", "f_n [Hz]", "damping", "tau [s]")
"""Column titles of :func:`pole_cells`."""


def sorted_poles(poles: Sequence[complex] | np.ndarray) -> np.ndarray:
    """``poles`` in table order: decreasing modulus, then complex before real at the same
    modulus (so a conjugate pair stays adjacent), then increasing imaginary part."""
    p = np.asarray(poles, dtype=complex).reshape(-1) + 0.0  # no -0.0 printed
    return np.array(sorted(p, key=lambda z: (-abs(z), -abs(z.imag), z.imag)), dtype=complex)


def pole_rows(poles: Sequence[complex] | np.ndarray, *, dt: float) -> list[dict[str, float]]:
    """One JSON-ready dict per pole (table order): ``re``, ``im``, ``abs``, ``angle_deg``,
    ``freq_hz`` (natural frequency; None for a pole at 0, infinitely fast), ``damping`` and
    ``tau_s`` (None when not stable)."""
    rows = []
    for z in sorted_poles(poles):
        if z == 0:  # ln 0 = -inf: infinitely fast, critically damped
            wn, zeta, tau = None, 1.0, 0.0
        else:
            s = complex(np.log(z)) / dt
            wn = abs(s)
            zeta = -s.real / wn if wn > 0 else 1.0
            tau = -1.0 / s.real if s.real < 0 else None
        rows.append({"re": float(z.real), "im": float(z.imag), "abs": float(abs(z)),
                     "angle_deg": float(np.degrees(np.angle(z))),
                     "freq_hz": None if wn is None else float(wn / (2 * math.pi)),
                     "damping": float(zeta),
                     "tau_s": tau})
    return rows


def pole_number(x: float, spec: str = ".4f") -> str:
    """A pole's modulus or part as text: ``spec`` (four decimals) up to a million, then four
    significant digits (a model file's pole at 8e302 is no 300-digit number), the sign as
    ``spec`` asks (``"+.4f"``: an imaginary part after the real one)."""
    return format(x, spec if abs(x) < 1e6 else ("+" if spec.startswith("+") else "") + ".4g")


def pole_cells(rows: Sequence[dict[str, float]]) -> list[tuple[str, ...]]:
    """The rows of :func:`pole_rows` as text cells under :data:`POLE_COLUMNS`."""
    cells = []
    for i, r in enumerate(rows):
        tau = "unstable" if r["tau_s"] is None and r["abs"] >= 1 else \
            "-" if r["tau_s"] is None else f"{r['tau_s']:.3g}"
        cells.append((str(i + 1), f"{pole_number(r['re'])}{pole_number(r['im'], '+.4f')}j",
                      pole_number(r["abs"]),
                      f"{r['angle_deg']:.1f}",
                      "-" if r["freq_hz"] is None else f"{r['freq_hz']:.2f}", f"{r['damping']:.3f}",
                      tau))
    return cells
