"""sysid/moesp.py on (all but) noise-free open-loop data: the poles, and Γ_f L_p of numerical rank
n whose projection of the past spans the true Γ_f.

A 1e-9 output noise keeps the joint Hankel matrix full rank here; exactly noise-free data (Y_f a
function of Z_p and U_f) are identified exactly too: tests/sysid/test_noise_free.py."""
from __future__ import annotations

import numpy as np
import scipy.linalg

from sysid.data import IOData
from sysid.factor import build_products
from sysid.model import StateSpaceModel
from sysid.moesp import moesp_signals, po_moesp

A = np.array([[0.8, 0.3, 0.0], [-0.3, 0.8, 0.0], [0.0, 0.0, 0.5]])
B = np.array([[1.0, 0.0], [0.0, 1.0], [0.5, -0.5]])
C = np.array([[1.0, 0.0, 1.0], [0.0, 1.0, -1.0]])
TRUE = StateSpaceModel(A=A, B=B, C=C, dt=0.01)


def _noise_free(n: int = 800) -> IOData:
    rng = np.random.default_rng(11)
    u = rng.normal(size=(n, 2))
    return IOData(u=u, y=TRUE.simulate(u) + 1e-9 * rng.normal(size=(n, 2)), dt=0.01)


def test_noise_free_open_loop_recovers_the_poles():
    model = po_moesp(_noise_free(), order=3, past=4, future=4, focus="prediction")
    true = np.sort_complex(np.linalg.eigvals(A))
    np.testing.assert_allclose(np.sort_complex(model.poles()), true, atol=1e-6)


def test_gamma_lp_spans_the_true_gamma_on_noise_free_data():
    products = build_products(_noise_free(), past=4, future=4)
    _, gamma_lp, sig = moesp_signals(products)
    # Z_p itself is rank deficient here (u_p and n states), so L_p is not unique: judge the
    # projection Γ_f L_p Z_p (in the factor's coordinates), which is.
    projection = gamma_lp @ sig.zp
    s = np.linalg.svd(projection, compute_uv=False)
    assert s[2] > 1e-3 * s[0] and s[3] < 1e-6 * s[0]  # rank n = 3 exactly
    gamma = np.vstack([C @ np.linalg.matrix_power(A, i) for i in range(4)])
    gamma_scaled = np.tile(1.0 / products.y_scale, 4)[:, None] * gamma  # the data were scaled
    u = np.linalg.svd(projection)[0][:, :3]
    angles = scipy.linalg.subspace_angles(u, gamma_scaled)
    assert angles.max() < 1e-6
