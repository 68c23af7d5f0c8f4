"""Known systems and simulated experiments for the sysid tests and benchmarks.

Every generator takes a ``numpy.random.Generator`` so results are reproducible. Systems are
:class:`sysid.StateSpaceModel` in innovation form; experiments return the :class:`IOData` plus
the truth needed to judge an identification (noise-free output, innovations, reference).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.data import IOData
from sysid.model import StateSpaceModel

__all__ = [
    "Experiment",
    "closed_loop",
    "open_loop",
    "pbsid_example1",
    "pbsid_example1_closed_loop",
    "pole_error",
    "random_stable_system",
]


@dataclass(frozen=True)
class Experiment:
    """Simulated data and its truth: ``y_clean`` is the deterministic response (N, l)."""

    data: IOData
    y_clean: np.ndarray
    e: np.ndarray
    r: np.ndarray
    system: StateSpaceModel


def pbsid_example1(*, dt: float = 1.0) -> StateSpaceModel:
    """The PBSID toolbox Example 1 system (van Wingerden), n=4, m=2, l=2, D=0."""
    a = np.array([[0.67, 0.67, 0, 0], [-0.67, 0.67, 0, 0], [0, 0, -0.67, -0.67],
                  [0, 0, 0.67, -0.67]])
    b = np.array([[0.6598, -0.5256], [1.9698, 0.4845], [4.3171, -0.4879], [-2.6436, -0.3416]])
    k = np.array([[-0.6968, -0.1474], [0.1722, 0.5646], [0.6484, -0.4660], [-0.9400, 0.1032]])
    c = np.array([[-0.3749, 0.0751, -0.5225, 0.5830], [-0.8977, 0.7543, 0.1159, 0.0982]])
    return StateSpaceModel(A=a, B=b, C=c, K=k, dt=dt, noise_cov=np.eye(2))


def random_stable_system(*, n_states: int, n_inputs: int, n_outputs: int, rng: np.random.Generator,
                         radius: tuple[float, float] = (0.5, 0.95), feedthrough: bool = False,
                         k_scale: float = 0.3, dt: float = 0.02) -> StateSpaceModel:
    """A random minimal stable system with poles of modulus in ``radius``.

    Complex pole pairs (and one real pole if n is odd) in a rotated block-diagonal A; K is
    drawn until ``A - K C`` is stable too (Assumption 1 of the thesis).
    """
    n, m, ell = n_states, n_inputs, n_outputs
    blocks = []
    for _ in range(n // 2):
        rho, th = rng.uniform(*radius), rng.uniform(0.1, 2.5)
        blocks.append(rho * np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]]))
    if n % 2:
        blocks.append(np.array([[rng.uniform(*radius) * rng.choice([-1, 1])]]))
    a0 = np.zeros((n, n))
    i = 0
    for blk in blocks:
        s = blk.shape[0]
        a0[i:i + s, i:i + s] = blk
        i += s
    q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    a = q @ a0 @ q.T
    b = rng.standard_normal((n, m))
    c = rng.standard_normal((ell, n))
    d = rng.standard_normal((ell, m)) if feedthrough else np.zeros((ell, m))
    for _ in range(100):
        k = k_scale * rng.standard_normal((n, ell))
        if np.max(np.abs(np.linalg.eigvals(a - k @ c))) < 0.95:
            break
    else:
        k = np.zeros((n, ell))
    return StateSpaceModel(A=a, B=b, C=c, D=d, K=k, dt=dt)


def _run(system: StateSpaceModel, *, u_fn, n_samples: int, e: np.ndarray, r: np.ndarray,
         x0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Simulate the innovation form with u(k) = u_fn(k, y_partial) (D-free feedback)."""
    a, b, c, d, k = system.A, system.B, system.C, system.D, system.K
    x = np.zeros(system.n_states) if x0 is None else x0
    u = np.empty((n_samples, system.n_inputs))
    y = np.empty((n_samples, system.n_outputs))
    for t in range(n_samples):
        y_free = c @ x + e[t]
        u[t] = u_fn(t, y_free)
        y[t] = y_free + d @ u[t]
        x = a @ x + b @ u[t] + k @ e[t]
    return u, y


def open_loop(system: StateSpaceModel, *, n_samples: int, rng: np.random.Generator,
              noise_std: float = 0.1, input_std: float = 1.0) -> Experiment:
    """White-input open-loop experiment: ``y = G u + H e`` with ``e ~ N(0, noise_std^2 I)``."""
    u = input_std * rng.standard_normal((n_samples, system.n_inputs))
    e = noise_std * rng.standard_normal((n_samples, system.n_outputs))
    _, y = _run(system, u_fn=lambda t, _y: u[t], n_samples=n_samples, e=e, r=u)
    return Experiment(data=IOData(u=u, y=y, dt=system.dt), y_clean=system.simulate(u),
                      e=e, r=u, system=system)


def closed_loop(system: StateSpaceModel, *, n_samples: int, rng: np.random.Generator,
                gain: np.ndarray | float = 0.25, r_std: float = 1.0,
                noise_std: float = 1.0) -> Experiment:
    """Closed loop ``u(k) = r(k) - F y(k)`` without delay (needs D = 0), white r and e.

    ``gain`` is ``F (m, l)`` or a scalar times the (m, l) identity pattern. The noise reaching
    ``y`` is coloured by the innovation form ``C (zI - A)^{-1} K e + e``.
    """
    f = np.asarray(gain, dtype=float)
    if f.ndim == 0:
        f = float(f) * np.eye(system.n_inputs, system.n_outputs)
    r = r_std * rng.standard_normal((n_samples, system.n_inputs))
    e = noise_std * rng.standard_normal((n_samples, system.n_outputs))
    u, y = _run(system, u_fn=lambda t, yt: r[t] - f @ yt, n_samples=n_samples, e=e, r=r)
    return Experiment(data=IOData(u=u, y=y, dt=system.dt), y_clean=system.simulate(u),
                      e=e, r=r, system=system)


#: Noise scale of the toolbox's closed-loop experiment (``e = 0.7.*e`` before ``lsim(CL, [r e])``).
PBSID_CLOSED_LOOP_NOISE_STD = 0.7


def pbsid_example1_closed_loop(*, rng: np.random.Generator, n_samples: int = 4000) -> Experiment:
    """The PBSID toolbox Example 1 closed-loop experiment, as the toolbox's script runs it.

    ``u = r - 0.25 y`` (``F = diag(0.25, 0.25)``, no delay), ``r ~ N(0, I)`` and innovations
    ``e ~ N(0, 0.7^2 I)``: the script draws ``e = randn(N, 2)`` for its open-loop experiment and
    scales it by 0.7 for the closed-loop one. Unit-variance ``e`` gives pole errors about
    1/0.7 times larger for every method.
    """
    return closed_loop(pbsid_example1(), n_samples=n_samples, rng=rng, gain=0.25,
                       noise_std=PBSID_CLOSED_LOOP_NOISE_STD)


def pole_error(true_poles: np.ndarray, est_poles: np.ndarray) -> float:
    """Largest distance from a true pole to its matched estimate (optimal assignment)."""
    from scipy.optimize import linear_sum_assignment

    cost = np.abs(np.asarray(true_poles)[:, None] - np.asarray(est_poles)[None, :])
    rows, cols = linear_sum_assignment(cost)
    return float(cost[rows, cols].max())
