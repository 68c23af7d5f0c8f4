"""IEM and PO-MOESP against known systems (issue 3, item 4)."""

from __future__ import annotations

import numpy as np
import pytest

import sysid
from tests.sysid.systems import (
    closed_loop,
    open_loop,
    pbsid_example1,
    pbsid_example1_closed_loop,
    pole_error,
    random_stable_system,
)


def markov(model: sysid.StateSpaceModel, count: int = 12) -> np.ndarray:
    """Similarity-invariant [D, CB, CAB, ...] and [CK, CAK, ...] stacked, (l, ...)."""
    blocks = [model.D]
    ak = np.eye(model.n_states)
    for _ in range(count):
        blocks.append(model.C @ ak @ np.hstack([model.B, model.K]))
        ak = model.A @ ak
    return np.hstack(blocks)


@pytest.fixture(scope="module")
def open_system() -> sysid.StateSpaceModel:
    return random_stable_system(n_states=4, n_inputs=2, n_outputs=3,
                                rng=np.random.default_rng(11), feedthrough=True)


@pytest.mark.parametrize("method", ["iem", "po_moesp"])
def test_open_loop_mimo_recovery(open_system, method: str) -> None:
    rng = np.random.default_rng(3)
    ex = open_loop(open_system, n_samples=4000, rng=rng, noise_std=0.1)
    ident = getattr(sysid, method)
    model = ident(ex.data, order=4, past=15, future=10, feedthrough=True)
    assert pole_error(open_system.poles(), model.poles()) < 1e-2
    u_new = rng.standard_normal((1500, 2))
    fit = sysid.fit_percent(open_system.simulate(u_new), model.simulate(u_new))
    assert fit.shape == (3,) and np.all(fit >= 98.0), fit
    assert model.provenance["method"] == {"iem": "iem", "po_moesp": "po-moesp"}[method]


def _feedback_case() -> tuple[sysid.StateSpaceModel, np.ndarray]:
    """Random 4-state 2x2 system, coloured noise (K), feedback F = 0.7 G(1)^-1 (strong)."""
    system = random_stable_system(n_states=4, n_inputs=2, n_outputs=2,
                                  rng=np.random.default_rng(2), radius=(0.6, 0.9),
                                  k_scale=0.6)
    dc = system.C @ np.linalg.solve(np.eye(4) - system.A, system.B)
    return system, 0.7 * np.linalg.pinv(dc)


def test_closed_loop_iem_consistent_po_moesp_biased() -> None:
    system, gain = _feedback_case()
    rng = np.random.default_rng(20)
    ex = closed_loop(system, n_samples=10000, rng=rng, gain=gain, noise_std=1.0)
    u_new = rng.standard_normal((2000, 2))
    truth = system.simulate(u_new)

    def fit(model: sysid.StateSpaceModel) -> np.ndarray:
        return sysid.fit_percent(truth, model.simulate(u_new))

    kw = {"order": 4, "past": 15, "future": 10}
    f_iem = fit(sysid.iem(ex.data, **kw))
    f_moesp = fit(sysid.po_moesp(ex.data, feedthrough=False, **kw))
    f_thesis = fit(sysid.iem(ex.data, bk_method="thesis", refine=False, **kw))
    assert np.all(f_iem >= 95.0), f_iem
    assert np.all(f_moesp < f_iem - 10.0), (f_moesp, f_iem)
    # the thesis' step 5 (Gamma-perp with U_f^+) is biased under feedback
    assert f_thesis.min() < f_iem.min() - 5.0, (f_thesis, f_iem)


def test_pbsid_example1_monte_carlo() -> None:
    """PBSID toolbox Example 1 as its script runs it: u = r - 0.25 y, e scaled by 0.7,
    N=4000, n=4, p=f=10, 20 Monte Carlo runs: mean worst-pole error at or below 0.005."""
    system = pbsid_example1()
    rng = np.random.default_rng(0)
    e_iem, e_moesp = [], []
    for _ in range(20):
        ex = pbsid_example1_closed_loop(rng=rng)
        e_iem.append(pole_error(system.poles(),
                                sysid.iem(ex.data, order=4, past=10, future=10).poles()))
        e_moesp.append(pole_error(system.poles(), sysid.po_moesp(
            ex.data, order=4, past=10, future=10, feedthrough=False).poles()))
    assert np.mean(e_iem) <= 0.005, e_iem
    assert np.mean(e_moesp) > 5 * np.mean(e_iem)


@pytest.mark.parametrize("feedthrough", [False, True])
def test_fast_path_matches_direct_lstsq(feedthrough: bool) -> None:
    system, gain = _feedback_case()
    rng = np.random.default_rng(5)
    flights = [closed_loop(system, n_samples=n, rng=rng, gain=gain).data for n in (900, 700)]
    kw = {"order": 4, "past": 8, "future": 6, "feedthrough": feedthrough}
    fast = sysid.iem(flights, **kw)
    direct = sysid.iem(flights, direct=True, **kw)
    sv_f = np.array(fast.provenance["singular_values"])
    sv_d = np.array(direct.provenance["singular_values"])
    assert np.max(np.abs(sv_f - sv_d) / sv_d[0]) < 1e-6
    mf, md = markov(fast), markov(direct)
    assert np.max(np.abs(mf - md)) < 1e-6 * np.max(np.abs(md))
    assert fast.provenance["path"] == "fast" and direct.provenance["path"] == "direct"


def test_qr_fallback_agrees_with_cholesky(open_system) -> None:
    ex = open_loop(open_system, n_samples=1500, rng=np.random.default_rng(8))
    kw = {"order": 4, "past": 10, "future": 8, "feedthrough": True}
    chol = sysid.iem(ex.data, factorization="cholesky", **kw)
    qr = sysid.iem(ex.data, factorization="qr", **kw)
    assert np.allclose(markov(chol), markov(qr), rtol=1e-7, atol=1e-9)


def test_channel_scaling_is_undone(open_system) -> None:
    """Identifying from PWM-count-sized inputs and milli-sized outputs gives the same
    physical model as from the raw data, scaled exactly (scaling is undone)."""
    ex = open_loop(open_system, n_samples=2000, rng=np.random.default_rng(4))
    su, sy = np.array([3000.0, 20.0]), np.array([1e-3, 1.0, 50.0])
    scaled = sysid.IOData(u=ex.data.u * su, y=ex.data.y * sy, dt=ex.data.dt)
    kw = {"order": 4, "past": 12, "future": 8, "feedthrough": True}
    raw = sysid.iem(ex.data, **kw)
    phys = sysid.iem(scaled, **kw)
    expect = raw.replace(B=raw.B / su, C=sy[:, None] * raw.C, D=sy[:, None] * raw.D / su,
                         K=raw.K / sy)
    assert np.allclose(markov(phys), markov(expect), rtol=1e-8,
                       atol=1e-10 * np.abs(markov(expect)).max())
    assert np.allclose(phys.noise_cov, raw.noise_cov * np.outer(sy, sy))
    assert phys.provenance["scaling"]["u_scale"] == pytest.approx(
        list(scaled.u.std(axis=0)))


def test_singular_values_show_the_order(open_system) -> None:
    ex = open_loop(open_system, n_samples=3000, rng=np.random.default_rng(9), noise_std=0.05)
    for method in ("iem", "po-moesp"):
        sv = sysid.singular_values(ex.data, past=12, future=8, method=method,
                                     feedthrough=True)
        assert sv.shape == (24,)
        assert sv[3] > 10 * sv[4], (method, sv[:6])


def test_several_flights_are_not_joined(open_system) -> None:
    """Each flight contributes its own Hankel columns (no column spans the junction)."""
    rng = np.random.default_rng(12)
    a = open_loop(open_system, n_samples=1500, rng=rng, noise_std=0.05).data
    b = open_loop(open_system, n_samples=1500, rng=rng, noise_std=0.05).data
    kw = {"order": 4, "past": 10, "future": 8, "feedthrough": True}
    both = sysid.iem([a, b], **kw)
    assert both.provenance["n_flights"] == 2
    assert both.provenance["n_columns"] == 2 * (1500 - 18 + 1)
    assert pole_error(open_system.poles(), both.poles()) < 1e-2


def test_iem_returns_k_and_noise_covariance() -> None:
    system, gain = _feedback_case()
    ex = closed_loop(system, n_samples=6000, rng=np.random.default_rng(21), gain=gain,
                     noise_std=0.5)
    model = sysid.iem(ex.data, order=4, past=15, future=10)
    assert model.K.shape == (4, 2) and np.any(model.K != 0)
    assert model.predictor_is_stable
    assert np.allclose(model.noise_cov, 0.25 * np.eye(2), atol=0.03)
    # CK, CAK are similarity invariant: compare with the truth
    ck = np.hstack([model.C @ np.linalg.matrix_power(model.A, i) @ model.K for i in range(3)])
    ck_true = np.hstack([system.C @ np.linalg.matrix_power(system.A, i) @ system.K
                         for i in range(3)])
    assert np.max(np.abs(ck - ck_true)) < 0.1 * np.max(np.abs(ck_true))


def test_kalman_gain_from_residuals_recovers_the_innovation_gain() -> None:
    """With the true states, w = K e and v = e, so the DARE gives back K and cov(e)."""
    from sysid.realize import Signals, kalman_gain_from_residuals

    system = pbsid_example1()
    rng = np.random.default_rng(6)
    n_samples = 20000
    u = rng.standard_normal((n_samples, 2))
    e = 0.5 * rng.standard_normal((n_samples, 2))
    x = np.zeros((n_samples + 1, 4))
    for k in range(n_samples):
        x[k + 1] = system.A @ x[k] + system.B @ u[k] + system.K @ e[k]
    y = x[:-1] @ system.C.T + e
    sig = Signals(zp=np.zeros((1, n_samples)), zp_next=np.zeros((1, n_samples)), u0=u.T,
                  y0=y.T, e0=e.T, uf=u.T, yf=y.T, n_columns=n_samples)
    gain, cov = kalman_gain_from_residuals(a=system.A, b=system.B, c=system.C, d=system.D,
                                           x=x[:-1].T, x_next=x[1:].T, sig=sig)
    assert np.allclose(gain, system.K, atol=0.03)
    assert np.allclose(cov, 0.25 * np.eye(2), atol=0.01)


@pytest.mark.parametrize("feedthrough", [False, True])
def test_refine_predictor_equals_brute_force_regression(feedthrough: bool) -> None:
    """The modal-feature normal equations give the same (B_K, D, K) as regressing y on the
    predictor responses to each unit parameter, simulated sample by sample (two flights)."""
    from sysid.realize import refine_predictor

    rng = np.random.default_rng(7)
    system = random_stable_system(n_states=3, n_inputs=2, n_outputs=2, rng=rng,
                                  feedthrough=feedthrough)
    flights = [open_loop(system, n_samples=n, rng=rng).data for n in (250, 180)]
    a_k = system.A - system.K @ system.C
    c = system.C
    n, m, ell = 3, 2, 2
    n_par = n * (m + ell) + (ell * m if feedthrough else 0) + n * 2

    def predictor(theta: np.ndarray, f_idx: int, u: np.ndarray, y: np.ndarray) -> np.ndarray:
        bk = theta[: n * (m + ell)].reshape(m + ell, n).T
        d = (theta[n * (m + ell):n * (m + ell) + ell * m].reshape(ell, m) if feedthrough
             else np.zeros((ell, m)))
        x = theta[n_par - n * (2 - f_idx):n_par - n * (1 - f_idx)].copy()
        out = np.empty_like(y)
        for k in range(len(u)):
            out[k] = c @ x + d @ u[k]
            x = a_k @ x + bk @ np.concatenate([u[k], y[k]])
        return out

    cols = []
    for j in range(n_par):
        unit = np.zeros(n_par)
        unit[j] = 1.0
        cols.append(np.concatenate([predictor(unit, i, fl.u, fl.y).ravel()
                                    for i, fl in enumerate(flights)]))
    target = np.concatenate([fl.y.ravel() for fl in flights])
    theta = np.linalg.lstsq(np.column_stack(cols), target, rcond=None)[0]
    bk_ref = theta[: n * (m + ell)].reshape(m + ell, n).T
    b_k, d, k = refine_predictor(a_k=a_k, c=c, flights=[(fl.u, fl.y) for fl in flights],
                                 feedthrough=feedthrough)
    assert np.allclose(b_k, bk_ref[:, :m], atol=1e-8)
    assert np.allclose(k, bk_ref[:, m:], atol=1e-8)
    if feedthrough:
        assert np.allclose(d, theta[n * (m + ell):n * (m + ell) + ell * m].reshape(ell, m),
                           atol=1e-8)
    # and with the true A_K, C the estimates are near the truth
    assert np.allclose(k, system.K, atol=0.15)
