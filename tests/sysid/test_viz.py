"""sysid.viz: what the .rrd holds equals what the model, compare() and sweep() report."""

from __future__ import annotations

import re

import numpy as np
import pytest

import sysid
from sysid import viz
from tests.sysid.systems import open_loop, pole_error, random_stable_system
from tests.viz.rrd import blueprint_entities, load


@pytest.fixture(scope="module")
def identified():
    rng = np.random.default_rng(7)
    system = random_stable_system(n_states=4, n_inputs=1, n_outputs=2, rng=rng)
    exp = open_loop(system, n_samples=1500, rng=rng, noise_std=0.05)
    data = sysid.IOData(u=exp.data.u, y=exp.data.y, dt=exp.data.dt, output_names=("p", "q"),
                        output_units=("deg/s", "deg/s"))
    model = sysid.iem(data, order=4, past=10, future=10)
    return system, data, model


def _points(static: dict) -> np.ndarray:
    pos = np.array(static["Points2D:positions"], dtype=float)
    return pos[:, 0] + 1j * pos[:, 1]


def _same_poles(a: np.ndarray, b: np.ndarray) -> float:
    return pole_error(np.asarray(a), np.asarray(b))


def test_singular_values_and_poles_equal_the_models(tmp_path, identified):
    system, data, model = identified
    path = tmp_path / "id.rrd"
    rec, url = viz.open_recording(name="id", mode="save", rrd_path=path)
    assert url is None
    viz.log_identification(rec=rec, model=model)
    viz.close_file(rec, path)
    ents = load(path)
    sv = ents["/sysid/order/singular_values"].static["BarChart:values"][0]["buffer"]
    np.testing.assert_allclose(sv, model.provenance["singular_values"], rtol=1e-12)
    np.testing.assert_allclose(sv, sysid.singular_values(data, past=10, future=10), rtol=1e-9)
    log10 = ents["/sysid/order/singular_values/log10"].static["BarChart:values"][0]["buffer"]
    np.testing.assert_allclose(log10, np.log10(np.divide(sv, min(sv))), rtol=1e-12,
                               atol=1e-12)
    chosen = ents["/sysid/order/singular_values/chosen"].static["BarChart:values"][0]["buffer"]
    np.testing.assert_allclose(chosen, np.asarray(sv)[:4], rtol=1e-12)
    text = ents["/sysid/order/order"].static["TextDocument:text"][0]
    assert text.startswith("order n = 4:")
    ratio = float(re.search(r"sigma_\(n\+1\) = ([0-9.e+-]+)", text).group(1))
    assert ratio == pytest.approx(sv[3] / sv[4], rel=1e-2)
    assert ratio > 5  # the known 4th-order system has a clear gap after sigma_4
    # Poles: exactly the model's (float32 storage), and near the true system's.
    a_poles = _points(ents["/sysid/poles/A"].static)
    assert len(a_poles) == 4 and _same_poles(a_poles, model.poles()) < 1e-6
    assert _same_poles(a_poles, system.poles()) < 0.05
    kc = _points(ents["/sysid/poles/A_minus_KC"].static)
    assert _same_poles(kc, model.predictor_poles()) < 1e-6
    labels = ents["/sysid/poles/A"].static["Points2D:labels"]
    assert labels == ["A1", "A2", "A3", "A4"]  # rows of the pole table
    table = ents["/sysid/poles/table"].static["TextDocument:text"][0]
    first = sysid.pole_format.sorted_poles(model.poles())[0]
    assert f"| A1 | {first.real:.4f}{first.imag:+.4f}j | {abs(first):.4f} |" in table
    circle = np.array(ents["/sysid/poles/unit_circle"].static["LineStrips2D:strips"][0])
    np.testing.assert_allclose(np.hypot(circle[:, 0], circle[:, 1]), 1.0, atol=1e-6)
    assert any(e.startswith("/view/") for e in blueprint_entities(path))


def test_compare_series_and_fits(tmp_path, identified):
    _, data, model = identified
    sim = sysid.compare(model, data)
    pred = sysid.compare(model, data, horizon=5)
    path = tmp_path / "cmp.rrd"
    rec, _ = viz.open_recording(name="cmp", mode="save", rrd_path=path)
    viz.log_identification(rec=rec, model=model, comparisons=[sim, pred])
    viz.close_file(rec, path)
    ents = load(path, sort_by="t")
    for res, slug in ((sim, "simulation"), (pred, "prediction_5_step")):
        assert viz.mode_slug(res) == slug
        for j, name in enumerate(("p", "q")):
            meas = ents[f"/sysid/{slug}/exp0/{name}/measured"]
            mod = ents[f"/sysid/{slug}/exp0/{name}/model"]
            np.testing.assert_allclose(meas.scalars(), data.y[:, j], rtol=1e-12)
            np.testing.assert_allclose(mod.scalars(), res.y_model[0][:, j], rtol=1e-12)
            np.testing.assert_allclose(mod.times["t"], np.arange(len(data.y)) * data.dt,
                                       atol=1e-9)
            label = mod.static["SeriesLines:names"][0]
            fit = float(re.search(r"fit (-?[0-9.]+) %", label).group(1))
            assert fit == pytest.approx(res.fits[0, j], abs=0.005)
            assert "[deg/s]" in label
        summary = ents[f"/sysid/{slug}/summary"].static["TextDocument:text"][0]
        assert summary == res.summary()
    assert sim.fit.min() > 90  # a correct model of a known system: the plot shows a good fit


def test_validation_comparisons_have_entities_of_their_own(tmp_path, identified):
    """The same mode on the identification and on validation data: both kept, each under its
    own path with its own series, names and summary; one mode twice in one set is refused."""
    _, data, model = identified
    ident, val = (sysid.IOData(u=data.u[a:b], y=data.y[a:b], dt=data.dt,
                               output_names=("p", "q")) for a, b in ((0, 900), (900, 1500)))
    on_ident, on_val = sysid.compare(model, ident), sysid.compare(model, val)
    path = tmp_path / "val.rrd"
    rec, _ = viz.open_recording(name="val", mode="save", rrd_path=path)
    viz.log_identification(rec=rec, model=model, comparisons=[on_ident], validation=[on_val])
    viz.close_file(rec, path)
    ents = load(path, sort_by="t")
    for base, res, d in (("/sysid", on_ident, ident), ("/sysid/validation", on_val, val)):
        mod = ents[f"{base}/simulation/exp0/q/model"]
        np.testing.assert_allclose(mod.scalars(), res.y_model[0][:, 1], rtol=1e-12)
        np.testing.assert_allclose(ents[f"{base}/simulation/exp0/q/measured"].scalars(),
                                   d.y[:, 1], rtol=1e-12)
        assert len(mod.times["t"]) == len(d.y)
        assert f"(fit {res.fits[0, 1]:.2f} %)" in mod.static["SeriesLines:names"][0]
        assert ents[f"{base}/simulation/summary"].static["TextDocument:text"][0] == \
            res.summary()
    assert on_ident.summary() != on_val.summary()
    rec, _ = viz.open_recording(name="twice", mode="save", rrd_path=tmp_path / "twice.rrd")
    try:
        with pytest.raises(sysid.ParameterError, match="simulation given more than once"):
            viz.log_identification(rec=rec, model=model, comparisons=[on_ident, on_val])
    finally:
        viz.close_file(rec, tmp_path / "twice.rrd")


def test_compare_two_experiments(tmp_path, identified):
    _, data, model = identified
    halves = [sysid.IOData(u=data.u[a:b], y=data.y[a:b], dt=data.dt, output_names=("p", "q"))
              for a, b in ((0, 700), (700, 1500))]
    res = sysid.compare(model, halves)
    path = tmp_path / "two.rrd"
    rec, _ = viz.open_recording(name="two", mode="save", rrd_path=path)
    viz.log_compare(rec=rec, result=res, dt=data.dt)
    viz.close_file(rec, path)
    ents = load(path, sort_by="t")
    for e, half in enumerate(halves):
        mod = ents[f"/sysid/simulation/exp{e}/q/model"]
        np.testing.assert_allclose(mod.scalars(), res.y_model[e][:, 1], rtol=1e-12)
        assert mod.times["t"][-1] == pytest.approx((len(half.y) - 1) * data.dt)
        assert f"(fit {res.fits[e, 1]:.2f} %)" in mod.static["SeriesLines:names"][0]


def test_sweep_pole_clouds(tmp_path, identified):
    _, data, _ = identified
    result = sysid.sweep(data, pasts=[8, 10], futures=[6, 8], orders=[3, 4])
    path = tmp_path / "sweep.rrd"
    rec, _ = viz.open_recording(name="sweep", mode="save", rrd_path=path)
    counts = viz.log_sweep_poles(rec=rec, result=result)
    viz.close_file(rec, path)
    ents = load(path)
    assert counts == {3: 4, 4: 4}
    for n in (3, 4):
        rows = [r for r in result.rows if r.order == n and r.error is None]
        logged = _points(ents[f"/sysid/sweep/poles/order_{n}"].static)
        expected = np.concatenate([r.poles for r in rows])
        assert len(logged) == n * len(rows)
        assert _same_poles(logged, expected) < 1e-6
        color = ents[f"/sysid/sweep/poles/order_{n}"].static["Points2D:colors"][0]
        assert color & 0xFF == 40  # translucent: overlapping poles look darker
    assert ents["/sysid/sweep/table"].static["TextDocument:text"][0] == result.table()


def test_open_recording_errors(tmp_path):
    with pytest.raises(sysid.ParameterError, match="view mode 'web' is unknown"):
        viz.open_recording(name="x", mode="web")
    with pytest.raises(sysid.ParameterError, match="needs rrd_path"):
        viz.open_recording(name="x", mode="save")
