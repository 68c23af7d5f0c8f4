"""sysid/realize.py on exact inputs: A, C from an exact Γ_f, B, D, K from exact states, and the
order check's messages."""
from __future__ import annotations

import numpy as np
import pytest

from sysid.errors import OrderError
from sysid.realize import Signals, ac_from_gamma, bdk_from_states, check_order

RNG = np.random.default_rng(3)
A = np.array([[0.9, 0.2, 0.0], [-0.1, 0.8, 0.1], [0.0, 0.05, 0.5]])
B = np.array([[1.0, 0.0], [0.3, 1.0], [0.0, 0.5]])
C = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
D = np.array([[0.2, 0.0], [0.0, 0.0]])
K = np.array([[0.3, 0.0], [0.0, 0.2], [0.1, 0.1]])


def _gamma(a: np.ndarray, c: np.ndarray, future: int) -> np.ndarray:
    return np.vstack([c @ np.linalg.matrix_power(a, i) for i in range(future)])


def test_ac_from_exact_gamma_recovers_the_system_up_to_similarity():
    t = RNG.normal(size=(3, 3))  # any basis: Γ T is as exact as Γ
    a, c = ac_from_gamma(_gamma(A, C, future=5) @ t, n_outputs=2)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(a)),
                               np.sort_complex(np.linalg.eigvals(A)), atol=1e-9)
    np.testing.assert_allclose(c, C @ t, atol=1e-9)


def test_bdk_from_exact_states_recovers_b_d_k():
    n_cols = 400
    x = RNG.normal(size=(3, n_cols))
    u0 = RNG.normal(size=(2, n_cols))
    e0 = RNG.normal(size=(2, n_cols))
    x_next = A @ x + B @ u0 + K @ e0
    y0 = C @ x + D @ u0 + e0
    empty = np.zeros((0, n_cols))
    sig = Signals(zp=empty, zp_next=empty, u0=u0, y0=y0, e0=e0, uf=empty, yf=empty,
                  n_columns=n_cols)
    b, d, k = bdk_from_states(a=A, c=C, x=x, x_next=x_next, sig=sig, feedthrough=True)
    np.testing.assert_allclose(b, B, atol=1e-9)
    np.testing.assert_allclose(d, D, atol=1e-9)
    np.testing.assert_allclose(k, K, atol=1e-9)
    _, d0, _ = bdk_from_states(a=A, c=C, x=x, x_next=x_next, sig=sig, feedthrough=False)
    assert not d0.any()


@pytest.mark.parametrize(("order", "past", "future", "needle"), [
    (0, 5, 5, "positive integer"),
    (True, 5, 5, "positive integer"),
    (9, 5, 4, "lower the order or use future >= 6"),   # (f-1) l = 6 < p (m+l) = 20
    (9, 2, 20, "lower the order or use past >= 3"),   # p (m+l) = 8 < (f-1) l = 38
])
def test_check_order_names_the_limit_and_the_fix(order, past, future, needle):
    with pytest.raises(OrderError, match=needle) as err:
        check_order(order=order, past=past, future=future, n_inputs=2, n_outputs=2)
    assert "\n" not in str(err.value)


def test_check_order_accepts_the_rank_limit():
    check_order(order=6, past=5, future=4, n_inputs=2, n_outputs=2)
