"""sysid.finish: from Γ_f and Γ_f L_p to (A, B, C, D, K), the step IEM and PO-MOESP share.

The tests hand :func:`finish` the exact Γ_f and Γ_f L_p of a known system whose predictor
``A - K C`` is nilpotent, so the past ``p = 2`` samples give the state exactly; every estimate
can then be checked against the truth to rounding. The end-to-end behaviour of the focus and
stability modes through ``sysid.iem`` / ``sysid.po_moesp`` is in ``test_focus_stability.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

from sysid.errors import ParameterError
from sysid.finish import finish
from sysid.realize import Signals
from sysid.stability import MARGINAL_RADIUS

PAST, FUTURE = 2, 4
NILPOTENT = np.array([[0.0, 1.0], [0.0, 0.0]])  # A - K C: the state is a function of 2 samples
C = np.array([[1.0, 0.0]])
B = np.array([[1.0], [0.5]])
D = np.array([[0.3]])


@dataclass(frozen=True)
class Exact:
    a: np.ndarray
    k: np.ndarray
    gamma: np.ndarray
    gamma_lp: np.ndarray
    sig: Signals
    u: np.ndarray
    y: np.ndarray
    e: np.ndarray


def exact(*, k: np.ndarray, n: int = 400, seed: int = 0, e_scale: float = 1.0) -> Exact:
    """Data of ``x+ = A x + B u + K e, y = C x + D u + e`` with ``A = NILPOTENT + K C``, and the
    exact Γ_f, Γ_f L_p and signals (``e0`` the true innovations times ``e_scale``)."""
    a = NILPOTENT + k @ C
    rng = np.random.default_rng(seed)
    u, e = rng.standard_normal((n, 1)), 0.5 * rng.standard_normal((n, 1))
    x, y = np.zeros(2), np.zeros((n, 1))
    for t in range(n):
        y[t] = C @ x + D @ u[t] + e[t]
        x = a @ x + B @ u[t] + k @ e[t]
    w = np.hstack([u, y])  # channels [u; y], the past window oldest sample first
    g = np.hstack([B - k @ D, k])  # predictor form: x+ = NILPOTENT x + (B - K D) u + K y
    lp = np.hstack([np.linalg.matrix_power(NILPOTENT, PAST - 1 - i) @ g for i in range(PAST)])
    cols = np.arange(PAST, n - 1)

    def past(shift: int) -> np.ndarray:
        return np.stack([w[t + shift - PAST:t + shift].reshape(-1) for t in cols], axis=1)

    gamma = np.vstack([C @ np.linalg.matrix_power(a, i) for i in range(FUTURE)])
    sig = Signals(zp=past(0), zp_next=past(1), u0=u[cols].T, y0=y[cols].T,
                  e0=e_scale * e[cols].T, uf=np.empty((0, cols.size)),
                  yf=np.empty((0, cols.size)), n_columns=cols.size)
    return Exact(a=a, k=k, gamma=gamma, gamma_lp=gamma @ lp, sig=sig, u=u, y=y, e=e[cols])


K_STABLE = np.array([[1.2], [-0.5]])  # A has poles 0.6 ± 0.37j


def _finish(ex: Exact, **kw):
    args = {"feedthrough": True, "focus": "prediction", "stability": "free",
            "flights": [(ex.u, ex.y)]}
    return finish(gamma=ex.gamma, gamma_lp=ex.gamma_lp, sig=ex.sig, **{**args, **kw})


def test_exact_gamma_gives_the_true_system():
    ex = exact(k=K_STABLE)
    fin = _finish(ex)
    for est, true in ((fin.a, ex.a), (fin.b, B), (fin.c, C), (fin.d, D), (fin.k, ex.k)):
        np.testing.assert_allclose(est, true, atol=1e-10)
    np.testing.assert_allclose(fin.noise_cov, ex.e.T @ ex.e / len(ex.e))
    assert fin.notes == {"bd": "state regression", "K": "state regression"}
    assert not fin.moved and len(fin.x0) == 1 and not fin.x0[0].any()


def test_without_feedthrough_d_is_zero():
    ex = exact(k=K_STABLE)
    fin = _finish(ex, feedthrough=False)
    assert fin.d.shape == (1, 1) and not fin.d.any()
    np.testing.assert_allclose(fin.a, ex.a, atol=1e-10)  # A, C do not depend on it


def test_an_unstable_predictor_is_replaced_by_the_kalman_gain():
    """Innovations estimated ten times too small make the regressed K ten times too large and
    A - K C unstable (poles 11.2, 0.4); the Kalman gain of the state residuals is the true K
    again, with the true innovation covariance."""
    ex = exact(k=K_STABLE, e_scale=0.1)
    fin = _finish(ex)
    assert fin.notes["K"] == "Kalman gain (DARE) of the state residuals"
    np.testing.assert_allclose(fin.k, ex.k, atol=1e-8)
    assert max(abs(np.linalg.eigvals(fin.a - fin.k @ fin.c))) < 1.0
    np.testing.assert_allclose(fin.noise_cov, ex.e.T @ ex.e / len(ex.e), rtol=1e-8)


def test_fixed_b_d_regress_only_k_and_refuse_simulation_focus():
    ex = exact(k=K_STABLE)
    fin = _finish(ex, bd=(2 * B, D))
    assert fin.notes["bd"] == "thesis eq. 3.15"
    np.testing.assert_array_equal(fin.b, 2 * B)  # kept as given, not re-estimated
    np.testing.assert_array_equal(fin.d, D)
    with pytest.raises(ParameterError, match="variant='thesis'"):
        _finish(ex, bd=(B, D), focus="simulation")


def test_simulation_focus_fits_b_d_and_one_x0_per_flight_by_output_error():
    """The flights' deterministic part (B2, D2, each from its own x0) differs from the
    innovation data's B, D: the simulation focus takes B, D from the flights, keeps A, C, K."""
    ex = exact(k=K_STABLE)
    b2, d2 = np.array([[-0.4], [2.0]]), np.array([[0.7]])
    rng = np.random.default_rng(1)
    flights, x0s = [], [np.array([1.0, -2.0]), np.array([-0.5, 3.0])]
    for x0 in x0s:
        u = rng.standard_normal((300, 1))
        x, y = x0.copy(), np.empty((300, 1))
        for t in range(300):
            y[t] = C @ x + d2 @ u[t]
            x = ex.a @ x + b2 @ u[t]
        flights.append((u, y))
    fin = _finish(ex, focus="simulation", flights=flights)
    assert fin.notes["bd"] == "output error (simulation focus), x0 per flight"
    np.testing.assert_allclose(fin.b, b2, atol=1e-8)
    np.testing.assert_allclose(fin.d, d2, atol=1e-8)
    for est, true in zip(fin.x0, x0s, strict=True):
        np.testing.assert_allclose(est, true, atol=1e-8)
    np.testing.assert_allclose(fin.k, ex.k, atol=1e-10)


def test_stability_is_applied_to_a_before_b_d_k_are_regressed():
    """A pole at 1.004 (an integrator's estimate) is moved to MARGINAL_RADIUS by "auto"; the
    other pole and C stay, and B, D, K are regressed for the moved A."""
    k_int = np.array([[1.904], [-0.9036]])  # A: z^2 - 1.904 z + 0.9036, poles 1.004 and 0.9
    ex = exact(k=k_int)
    np.testing.assert_allclose(np.sort(abs(np.linalg.eigvals(ex.a))), [0.9, 1.004])
    fin = _finish(ex, stability="auto")
    assert [(round(abs(p), 6), round(abs(q), 6)) for p, q in fin.moved] == [
        (1.004, MARGINAL_RADIUS)]
    np.testing.assert_allclose(np.sort(abs(np.linalg.eigvals(fin.a))), [0.9, MARGINAL_RADIUS])
    np.testing.assert_array_equal(fin.c, C)
    free = _finish(ex, stability="free")
    assert not free.moved and not np.allclose(fin.b, free.b)  # B re-regressed for the new A
