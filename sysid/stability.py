"""Stability of an identified A: what the default does, and strict stability on request.

A quadrotor's rate and attitude dynamics from motor commands are near-integrating: their true
poles sit on the unit circle, so a finite-sample estimate puts them just inside or just outside.
A pole at ``|z| = 1.008`` is physics plus variance; a model that *simulates* with it drifts off.
The modes (``stability=``):

* ``"auto"`` (default): poles with ``1 < |z| <= 1 + NEAR_BAND`` are estimation noise. Within
  ``NEAR_BAND`` of ``z = 1`` they are an integrator's estimate and are moved radially onto
  ``|z| = MARGINAL_RADIUS`` (a time constant of 1000 samples: an integrator over any
  validation window). Elsewhere (an oscillation, or near ``z = -1``) they are a lightly damped
  mode estimated just outside and are reflected as ``"enforce"`` does: at ``MARGINAL_RADIUS``
  they would ring undamped through any simulation. Poles further out are kept, with a warning
  that does not guess the cause: an unstable plant (closed-loop identification exists for
  those) or a model with more states than the data support (an over-fitted order puts spare
  poles anywhere, e.g. 1.99 and 1.18 at order 18 on a 4-state system).
* ``"enforce"``: every pole strictly inside, as MATLAB's ``EnforceStability``: a pole outside
  is reflected, :math:`z \\to 1/\\bar z`, and capped at ``MARGINAL_RADIUS``.
* ``"free"``: A as the subspace step estimated it.

A is changed in its real Schur basis (``A = Q T Q^T``; a real pole or a conjugate pair is a
diagonal block of T), so C, and everything estimated after A (B, D, K by the method's own
regression, or by output error), stay consistent: callers re-estimate them for the new A.
"""

from __future__ import annotations

import logging
from typing import Literal

import numpy as np
import scipy.linalg

from sysid.errors import ParameterError

__all__ = ["MARGINAL_RADIUS", "NEAR_BAND", "STABILITY_MODES", "Stability", "stabilize"]

log = logging.getLogger(__name__)

Stability = Literal["auto", "enforce", "free"]
STABILITY_MODES: tuple[str, ...] = ("auto", "enforce", "free")

#: Radius a near-integrating or reflected pole is put at.
MARGINAL_RADIUS = 0.999
#: ``"auto"`` treats poles with ``1 < |z| <= 1 + NEAR_BAND`` as noise, and those of them within
#: ``NEAR_BAND`` of ``z = 1`` as integrators.
NEAR_BAND = 0.1


def check_stability(stability: object) -> None:
    """Raise :class:`ParameterError` unless ``stability`` is one of the modes."""
    if stability not in STABILITY_MODES:
        raise ParameterError(f"stability={stability!r}; use one of {STABILITY_MODES}")


def _target_radius(pole: complex, mode: str) -> float | None:
    """New radius for ``pole``, or None to keep it."""
    radius = abs(pole)
    if mode == "free" or radius <= 1.0:
        return None
    if mode == "auto":
        if radius > 1.0 + NEAR_BAND:
            return None
        if abs(pole - 1.0) <= NEAR_BAND * (1.0 + 1e-9):  # the band edge, to rounding
            return MARGINAL_RADIUS
    return min(1.0 / radius, MARGINAL_RADIUS)


def stabilize(a: np.ndarray, *, mode: Stability
              ) -> tuple[np.ndarray, list[tuple[complex, complex]]]:
    """``(A', moved)``: A with its poles treated as ``mode`` says (module docstring).

    ``moved`` lists ``(old pole, new pole)`` for each pole changed (one entry per conjugate
    pair, upper half plane). ``A'`` is A when nothing moved. For ``"enforce"`` a pole on the
    unit circle (``|z| = 1``) is also pulled in to ``MARGINAL_RADIUS``.
    """
    check_stability(mode)
    lam = np.linalg.eigvals(a)
    if mode == "free" or lam.size == 0:
        return a, []
    limit = MARGINAL_RADIUS if mode == "enforce" else 1.0
    if np.max(np.abs(lam)) <= limit:
        return a, []
    t, q = scipy.linalg.schur(a, output="real")
    n = t.shape[0]
    moved: list[tuple[complex, complex]] = []
    i = 0
    while i < n:
        size = 2 if i + 1 < n and abs(t[i + 1, i]) > 0.0 else 1
        blk = t[i:i + size, i:i + size]
        pole = complex(np.linalg.eigvals(blk)[0])
        radius = abs(pole)
        new = _new_radius(pole, mode)
        if new is not None:
            scale = new / radius
            t[i:i + size, i:i + size] = blk * scale
            # scaling the block scales the coupling to later blocks consistently: keep T's
            # upper part as it is (it only changes eigenvectors, not eigenvalues)
            pole_up = complex(pole.real, abs(pole.imag))
            moved.append((pole_up, pole_up * scale))
        elif radius > 1.0:
            log.warning("pole at |z| = %.3f kept: too far outside the unit circle to be noise "
                        "around an integrator; either the plant is unstable or the model has "
                        "more states than the data support (a lower order may avoid it; "
                        "--stability enforce, stability='enforce' in Python, moves it "
                        "inside)", radius)
        i += size
    if not moved:
        return a, []
    eigen = _moved_in_eigenbasis(a, mode) if _coincide(t) else None
    return (q @ t @ q.T if eigen is None else eigen), moved


def _coincide(t: np.ndarray) -> bool:
    """Whether two poles of the (real Schur) T coincide: then its coupling may make them a
    Jordan block (:func:`_moved_in_eigenbasis`)."""
    lam = np.linalg.eigvals(t)
    gaps = np.abs(lam[:, None] - lam[None, :]) + np.eye(lam.size)
    return bool((gaps <= 1e-9).any())


#: Largest condition number of A's eigenvectors for moving its poles in the eigenbasis.
_EIGEN_COND = 1e6
#: Two poles moved onto one value whose eigenvectors are closer to parallel than this
#: (|cos| of their angle) are one chain, nearly a Jordan block in the data already: a double
#: integrator (rate and angle at 1.0004 and 1.0001: 0.989) keeps its coupling. The separate
#: modes of the closed-loop models that motivated the eigenbasis read 0.14 to 0.95.
_CHAIN_COS = 0.98


def _new_radius(pole: complex, mode: str) -> float | None:
    """The radius ``pole`` is moved to under ``mode``, or None to keep it."""
    new = _target_radius(pole, mode)
    if mode == "enforce" and new is None and abs(pole) > MARGINAL_RADIUS:
        new = MARGINAL_RADIUS
    return new


def _moved_in_eigenbasis(a: np.ndarray, mode: str) -> np.ndarray | None:
    """``A`` with its poles moved as ``mode`` says and every eigenvector kept,
    :math:`V \\operatorname{diag}(\\lambda') V^{-1}`, or None when A's eigenvectors are too
    ill-conditioned (a nearly defective A: the Schur form's scaling is used then). Used where
    moved poles coincide: scaling blocks of the Schur form keeps their coupling, so two poles
    moved onto one radius (1.0024 and 1.0725 both onto 0.999) became a Jordan block, a double
    integrator the data never showed; the eigenbasis keeps them two modes. Not where their
    eigenvectors are nearly parallel (:data:`_CHAIN_COS`): there the data show one chain, and
    the Schur form keeps it one. Elsewhere the Schur
    form's scaling stays (it changes A by no more than the poles move, whatever the
    eigenvectors' conditioning: moving every A in the eigenbasis cost DaISy dryer 0.6 points
    and flutter's no-knobs model 134)."""
    lam, vec = np.linalg.eig(a)
    if not np.isfinite(vec).all() or np.linalg.cond(vec) > _EIGEN_COND:
        return None
    new = lam.copy()
    for i, pole in enumerate(lam):
        radius = _new_radius(complex(pole), mode)
        if radius is not None:
            new[i] = pole * (radius / abs(pole))
    unit = vec / np.linalg.norm(vec, axis=0)
    for i, j in zip(*np.triu_indices(lam.size, k=1), strict=True):
        if abs(new[i] - new[j]) <= 1e-9 and abs(np.vdot(unit[:, i], unit[:, j])) > _CHAIN_COS:
            return None  # one chain the data show (rate and angle): its coupling is kept
    return np.ascontiguousarray(((vec * new) @ np.linalg.inv(vec)).real)
