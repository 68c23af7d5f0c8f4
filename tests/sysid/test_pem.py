"""Prediction-error refinement (sysid/pem.py): modal parameterisation, fallback, accuracy."""

from __future__ import annotations

import numpy as np

import sysid
from sysid.pem import _a_k, modal_form, pem_refine
from sysid.realize import predictor_fit

from .systems import closed_loop, open_loop, pbsid_example1, pole_error, random_stable_system

KW = {"order": 4, "past": 10, "future": 10}


def _flights(exp) -> list[tuple[np.ndarray, np.ndarray]]:
    return [(exp.data.u, exp.data.y)]


def _cost(model: sysid.StateSpaceModel, data: sysid.IOData) -> float:
    """Least one-step prediction-error cost over (B_K, K, x0) for the model's (A_K, C)."""
    ys = np.asarray(model.provenance["scaling"]["y_scale"])
    fit = predictor_fit(a_k=model.A - model.K @ model.C, c=model.C / ys[:, None],
                        flights=[(data.u, data.y / ys)], feedthrough=False, residuals=True)
    return float(np.sum(fit.errors[0] ** 2))


def test_modal_form_is_the_same_predictor_with_normalised_c():
    rng = np.random.default_rng(3)
    system = random_stable_system(n_states=5, n_inputs=2, n_outputs=3, rng=rng)
    a_k = system.A - system.K @ system.C
    par, sizes, c_mod, fixed = modal_form(a_k=a_k, c=system.C)
    assert sorted(sizes) == [1, 2, 2] and par.size == 5
    assert fixed.sum() == 5 and (~fixed).sum() == 3 * 5 - 5
    a_mod = _a_k(par, sizes)
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(a_mod)),
                               np.sort_complex(np.linalg.eigvals(a_k)), atol=1e-10)
    starts = np.cumsum([0, *sizes[:-1]])
    for j in range(5):  # fixed entries: 1 on a block's first column, 0 on its second
        assert np.all(c_mod[fixed[:, j], j] == (1.0 if j in starts else 0.0))
    flights = _flights(open_loop(system, n_samples=600, rng=rng))
    orig = predictor_fit(a_k=a_k, c=system.C, flights=flights, feedthrough=False,
                         residuals=True)
    modal = predictor_fit(a_k=a_mod, c=c_mod, flights=flights, feedthrough=False,
                          residuals=True)
    np.testing.assert_allclose(modal.errors[0], orig.errors[0], atol=1e-8)


def test_pem_moves_a_perturbed_model_to_the_truth():
    system = pbsid_example1()
    exp = closed_loop(system, n_samples=3000, rng=np.random.default_rng(1), gain=0.25)
    a_k = system.A - system.K @ system.C
    rng = np.random.default_rng(2)
    a_bad = system.A + 0.03 * rng.standard_normal(a_k.shape)
    mats = (a_bad, system.B, system.C, system.D, system.K, np.eye(2))
    (a, *_rest), status = pem_refine(matrices=mats, flights=_flights(exp), feedthrough=False,
                                     max_iterations=10)
    assert status.startswith("done")
    before = pole_error(system.poles(), np.linalg.eigvals(a_bad))
    after = pole_error(system.poles(), np.linalg.eigvals(a))
    assert before > 0.02 and after < 0.25 * before


def test_pem_keeps_the_input_model_when_the_predictor_is_unstable(caplog):
    system = pbsid_example1()
    exp = closed_loop(system, n_samples=500, rng=np.random.default_rng(0), gain=0.25)
    mats = (system.A, system.B, system.C, system.D, np.zeros((4, 2)) + 5.0, np.eye(2))
    out, status = pem_refine(matrices=mats, flights=_flights(exp), feedthrough=False)
    assert status.startswith("kept input model") and "unstable" in status
    assert all(o is m for o, m in zip(out, mats, strict=True))
    assert "PEM refinement skipped" in caplog.text


def test_pem_does_not_worsen_pbsid_example1_poles():
    system = pbsid_example1()
    rng = np.random.default_rng(0)
    base, refined = [], []
    for _ in range(4):
        data = closed_loop(system, n_samples=4000, rng=rng, gain=0.25).data
        plain = sysid.iem(data, **KW)
        pem = sysid.iem(data, pem=True, **KW)
        assert plain.provenance["pem"] == "off" and pem.provenance["pem"].startswith("done")
        base.append(pole_error(system.poles(), plain.poles()))
        refined.append(pole_error(system.poles(), pem.poles()))
        # the refined one-step predictor fits the (scaled) data better: the PEM criterion
        assert _cost(pem, data) < _cost(plain, data)
    assert np.mean(refined) <= np.mean(base)
