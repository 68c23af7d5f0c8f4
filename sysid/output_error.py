"""B, D and the initial states by output error, given A and C (simulation focus).

With A ``(n, n)`` and C ``(l, n)`` fixed, the deterministic model's simulated output

.. math::

    \\hat y(k) = C A^k x_0 + \\sum_{t<k} C A^{k-1-t} B u(t) + D u(k)

is linear in ``(B, D, x_0)`` (one ``x_0`` per flight), so minimising the simulation error
:math:`\\sum_k \\lVert y(k) - \\hat y(k) \\rVert^2` is one linear least-squares problem. This is
what MATLAB's ``n4sid`` does with ``Focus="simulation"`` and what makes a subspace model
*simulate* well on colored or real inputs, where the thesis' eq. 3.15
(:math:`\\Gamma^\\perp Y_f U_f^\\dagger`) amplifies the small error of :math:`\\Gamma^\\perp`.

The regressors are the responses of ``(A, e_i, C)`` to each input channel: with
``A = V Λ V^{-1}`` the response to ``u_j`` through mode ``a`` is one first-order filter
``z_{a j}(k) = Σ_{t<k} λ_a^{k-1-t} u_j(t)`` (``scipy.signal.lfilter``), and the regressor of
``B[i, j]`` at output ``o`` is ``Re Σ_a z_{a j}(k) (C V)[o, a] (V^{-1})[a, i]``. When A is not
safely diagonalisable (``cond(V) > 1e8``) the states are propagated by a plain recursion
instead. In closed loop the input is correlated with the noise and output error is biased
(see ``docs/sysid.md``, "Focus").
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator, Sequence

import numpy as np

__all__ = ["CHUNK", "POWER_FLOOR", "mode_power", "mode_powers", "output_error_bd"]

log = logging.getLogger(__name__)

#: Largest cond(V) of A's eigenvectors for the modal (filter) route.
_COND_MODAL = 1e8


#: Samples per block of the regression: memory is O(CHUNK l n m), not O(N l n m).
CHUNK = 8192


def _modal(a: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """``(lam (n,), t (n_modes, l, n))`` of the modal route, None when A is not safely
    diagonalisable (``cond(V) > 1e8``)."""
    lam, vec = np.linalg.eig(a)
    if not np.isfinite(vec).all() or np.linalg.cond(vec) > _COND_MODAL:
        return None
    t = np.einsum("oa,ai->aoi", c @ vec, np.linalg.inv(vec))  # (n_modes, l, n)
    return lam, t


def _real_product(z: np.ndarray, t_real: np.ndarray) -> np.ndarray:
    """``Re(z t)`` for complex ``z (K, a)`` and ``t (a, q)`` given as ``t_real = [Re t;
    -Im t] (2 a, q)``: one real matrix product (a complex one, or an einsum, is several times
    slower on long records)."""
    return np.concatenate([z.real, z.imag], axis=1) @ t_real


#: Powers of a stable mode below this magnitude are left 0: further on they reach the
#: subnormal numbers, where the filter gets stuck in a limit cycle of values near 1e-323 and
#: each operation costs a hundred times more (most of the powers' time on long records).
POWER_FLOOR = 1e-300


def _powers_kept(lam: complex, start: int, n_samples: int) -> int:
    """How many leading samples ``j`` have ``|lam| ** (start + j) >= POWER_FLOOR`` (all of
    them for ``|lam| >= 1`` or not finite)."""
    radius = abs(lam)
    if not radius < 1.0:
        return n_samples
    if radius == 0.0:
        return min(n_samples, 1) if start == 0 else 0
    last = math.floor(math.log(POWER_FLOOR) / math.log(radius))  # largest power kept
    return max(0, min(n_samples, last - start + 1))


def mode_power(lam: complex, n_samples: int, *, start: int = 0) -> np.ndarray:
    """``lam ** (start + j)`` for the leading ``j < n_samples`` down to :data:`POWER_FLOOR`
    (complex, as long as :func:`_powers_kept` says; the later ones are 0): one column of
    :func:`mode_powers`."""
    import scipy.signal  # where used: scipy.signal takes 0.5 s to import

    kept = _powers_kept(lam, start, n_samples)
    impulse = np.zeros(kept)
    if not kept:
        return impulse.astype(complex)
    impulse[0] = 1.0
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable mode's powers overflow
        out = scipy.signal.lfilter([1.0], [1.0, -lam], impulse)
        if start:
            out *= lam ** start
    return out


def mode_powers(lam: np.ndarray, n_samples: int, *, start: int = 0,
                modes: Sequence[int] | None = None) -> np.ndarray:
    """``(n_samples, len(lam))`` complex: ``lam[i] ** (start + j)`` in row ``j`` for the
    ``modes`` asked for (all by default; the others left 0), by one first-order filter of a
    unit impulse per mode: 5-6 times faster than numpy's complex power (184 ms for 1e5 samples
    of 12 modes, most of a one-step fit's time), within 1e-13 of it for ``|lam| <= 1``.
    Powers below :data:`POWER_FLOOR` are 0 (the filter stops there: the ones before are the
    same to the bit): :func:`mode_power`."""
    out = np.zeros((n_samples, lam.size), dtype=complex)
    for i in range(lam.size) if modes is None else modes:
        col = mode_power(lam[i], n_samples, start=start)
        out[:col.size, i] = col
    return out


def _responses(a: np.ndarray, c: np.ndarray, u: np.ndarray
               ) -> Iterator[tuple[int, np.ndarray, np.ndarray]]:
    """``(start, resp (K, l, n, m), free (K, l, n))`` block by block of :data:`CHUNK`
    samples: the output regressors of ``B[i, j]`` and of ``x0[i]`` (module docstring), by
    modal filtering (the filters' states carried from block to block), or by propagating
    ``X_j(k+1) = A X_j(k) + I u_j(k)`` when A is not safely diagonalisable."""
    import scipy.signal  # where used: scipy.signal takes 0.5 s to import

    n_samples, m = u.shape
    n = a.shape[0]
    modal = _modal(a, c)
    if modal is not None:
        lam, t = modal
        t_real = np.concatenate([t.real, -t.imag]).reshape(2 * lam.size, -1)  # (2 a, l n)
        zi = np.zeros((lam.size, 1, m), dtype=complex)
        for start in range(0, n_samples, CHUNK):
            block = u[start:start + CHUNK]
            z = np.empty((block.shape[0], m, lam.size), dtype=complex)
            for i, li in enumerate(lam):
                z[:, :, i], zi[i] = scipy.signal.lfilter([0.0, 1.0], [1.0, -li], block,
                                                         axis=0, zi=zi[i])
            with np.errstate(over="ignore", invalid="ignore"):  # left out below
                powers = mode_powers(lam, block.shape[0], start=start)
                k = block.shape[0]
                resp = _real_product(z.reshape(k * m, lam.size), t_real).reshape(k, m, -1, n)
                free = _real_product(powers, t_real).reshape(k, -1, n)
            yield start, resp.transpose(0, 2, 3, 1), free
        return
    xs, power, eye = np.zeros((m, n, n)), np.eye(n), np.eye(n)
    for start in range(0, n_samples, CHUNK):
        block = u[start:start + CHUNK]
        resp = np.empty((block.shape[0], c.shape[0], n, m))
        free = np.empty((block.shape[0], c.shape[0], n))
        with np.errstate(over="ignore", invalid="ignore"):  # growing rows: left out below
            for k, uk in enumerate(block):
                resp[k] = np.einsum("on,jni->oij", c, xs)
                free[k] = c @ power
                xs = a @ xs + eye[None] * uk[:, None, None]
                power = a @ power
        yield start, resp, free


def output_error_bd(*, a: np.ndarray, c: np.ndarray,
                    flights: Sequence[tuple[np.ndarray, np.ndarray]], feedthrough: bool,
                    estimate_x0: bool = True, residuals: bool = False
                    ) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """``B (n, m)``, ``D (l, m)`` and one ``x0 (n,)`` per flight minimising the simulation error.

    With ``residuals=True`` a fourth item is returned: the simulation errors ``y - yhat``
    ``(N_used, l)`` of each flight (samples left out, see below, are not in them).

    ``flights``: ``(u (N, m), y (N, l))`` each. ``feedthrough=False`` imposes ``D = 0``;
    ``estimate_x0=False`` imposes ``x0 = 0``. A with poles outside the unit circle makes the
    regressors grow without bound: such samples are left out (and logged), so the fit is then
    only over the start of each flight.
    """
    n, ell = a.shape[0], c.shape[0]
    m = flights[0][0].shape[1]
    n_b, n_d = n * m, (ell * m if feedthrough else 0)
    n_x = n if estimate_x0 else 0
    n_par = n_b + n_d + n_x * len(flights)

    def designs(f_idx: int, u: np.ndarray, y: np.ndarray
                ) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """``(design (K', l, n_par), y (K', l))`` block by block, samples left out dropped."""
        for start, resp, free in _responses(a, c, u):
            k = resp.shape[0]
            design = np.zeros((k, ell, n_par))
            design[:, :, :n_b] = resp.reshape(k, ell, n_b)
            if feedthrough:
                for o in range(ell):
                    design[:, o, n_b + o * m:n_b + (o + 1) * m] = u[start:start + k]
            if estimate_x0:
                x0 = n_b + n_d + n * f_idx
                design[:, :, x0:x0 + n] = free
            # NaN and inf fail the test too (the max propagates NaN): one pass over the block
            ok = np.abs(design).max(axis=(1, 2), initial=0.0) < 1e12
            if not ok.all():
                log.info("output error: %d samples left out (A unstable: responses too "
                         "large)", int((~ok).sum()))
                design = design[ok]
            yield design, y[start:start + k][ok]

    # normal equations of the column-equilibrated design: (n_par, n_par), solved by SVD
    # (rank-safe); forming them costs O(N l n_par^2), a tenth of an SVD of the design, and
    # block by block they hold O(CHUNK l n_par) values at a time
    gram, rhs_n = np.zeros((n_par, n_par)), np.zeros(n_par)
    for f_idx, (u, y) in enumerate(flights):
        for design, y_ok in designs(f_idx, u, y):
            rows = design.reshape(-1, n_par)
            gram += rows.T @ rows
            rhs_n += rows.T @ y_ok.reshape(-1)
    scale = np.sqrt(np.diag(gram)).copy()
    scale[scale == 0] = 1.0
    theta = np.linalg.lstsq(gram / np.outer(scale, scale), rhs_n / scale, rcond=None)[0] / scale
    # parameter i * m + j is B[i, j]; n_b + o * m + j is D[o, j]
    b = theta[:n_b].reshape(n, m)
    d = theta[n_b:n_b + n_d].reshape(ell, m) if feedthrough else np.zeros((ell, m))
    x0s = [theta[n_b + n_d + n * i:n_b + n_d + n * (i + 1)] if estimate_x0 else np.zeros(n)
           for i in range(len(flights))]
    if residuals:  # a second pass: the regressors are not kept
        errs = [np.concatenate([y_ok - dsg @ theta for dsg, y_ok in designs(f_idx, u, y)])
                if u.shape[0] else np.zeros((0, ell)) for f_idx, (u, y) in enumerate(flights)]
        return b, d, x0s, errs
    return b, d, x0s
