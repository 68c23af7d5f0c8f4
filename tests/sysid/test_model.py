"""StateSpaceModel behaviour and model files (IOData: test_data.py)."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import scipy.signal

import sysid
from tests.sysid.systems import pbsid_example1, random_stable_system


def test_model_shapes_are_checked_with_names() -> None:
    with pytest.raises(sysid.DimensionError, match=r"C has shape \(2, 3\); it must be \(l, n\)"):
        sysid.StateSpaceModel(A=np.eye(2), B=np.ones((2, 1)), C=np.ones((2, 3)))
    with pytest.raises(sysid.DimensionError, match="K has shape"):
        sysid.StateSpaceModel(A=np.eye(2), B=np.ones((2, 1)), C=np.ones((1, 2)), K=np.ones(3))


def test_simulate_matches_scipy_dlsim() -> None:
    rng = np.random.default_rng(1)
    sys_ = random_stable_system(n_states=4, n_inputs=2, n_outputs=3, rng=rng, feedthrough=True)
    u = rng.standard_normal((200, 2))
    x0 = rng.standard_normal(4)
    _, y_ref, _ = scipy.signal.dlsim((sys_.A, sys_.B, sys_.C, sys_.D, sys_.dt), u, x0=x0)
    assert np.allclose(sys_.simulate(u, x0=x0), y_ref, rtol=1e-10, atol=1e-10)


def test_poles_and_predictor_stability() -> None:
    m = pbsid_example1()
    assert np.allclose(np.sort(np.abs(m.poles())), 0.67 * np.sqrt(2))
    assert m.is_stable and m.predictor_is_stable
    bad = m.replace(K=np.zeros((4, 2)) + 5.0)
    assert not bad.predictor_is_stable


@pytest.mark.parametrize("suffix", [".h5", ".json", ".mat"])
def test_save_load_round_trip(tmp_path, suffix: str) -> None:
    m = pbsid_example1().replace(
        provenance={"method": "iem", "past": 10, "horizons": [10, 10]},
        input_names=("m1", "m2"), input_units=("PWM", "PWM"), output_units=("deg/s", "g"))
    back = sysid.load_model(m.save(tmp_path / f"model{suffix}"))
    for name in ("A", "B", "C", "D", "K", "noise_cov"):
        assert np.array_equal(getattr(back, name), getattr(m, name)), name
    assert back.provenance == m.provenance
    assert back.input_names == ("m1", "m2") and back.output_units == ("deg/s", "g")
    assert back.dt == m.dt


def test_h5_datasets_carry_units(tmp_path) -> None:
    import h5py

    m = pbsid_example1().replace(input_units=("PWM", "PWM"), output_units=("deg/s", "g"))
    path = m.save(tmp_path / "m.h5")
    with h5py.File(path) as f:
        assert f.attrs["dt_unit"] == "s"
        assert json.loads(f["B"].attrs["col_units"]) == ["PWM", "PWM"]
        assert json.loads(f["C"].attrs["row_units"]) == ["deg/s", "g"]


def test_bad_model_files(tmp_path) -> None:
    with pytest.raises(sysid.ModelFileError, match="does not exist"):
        sysid.load_model(tmp_path / "missing.h5")
    (tmp_path / "x.txt").write_text("x")
    with pytest.raises(sysid.ModelFileError, match="suffix"):
        sysid.load_model(tmp_path / "x.txt")
    for suffix in (".mat", ".h5", ".json"):
        (tmp_path / f"empty{suffix}").write_bytes(b"")
        with pytest.raises(sysid.ModelFileError, match="not a readable sysid model"):
            sysid.load_model(tmp_path / f"empty{suffix}")
    d = pbsid_example1().to_dict()
    d["version"] = 99
    with pytest.raises(sysid.ModelFileError, match="newer"):
        sysid.StateSpaceModel.from_dict(d)


def test_to_control_matches_frequency_response() -> None:
    control = pytest.importorskip("control")
    m = pbsid_example1()
    ss = m.to_control()
    z = np.exp(1j * 0.3)
    g = m.C @ np.linalg.solve(z * np.eye(4) - m.A, m.B) + m.D
    assert np.allclose(control.evalfr(ss, z), g)
    assert ss.dt == m.dt


def test_an_unstable_models_response_overflows_without_numpy_warnings():
    model = sysid.StateSpaceModel(A=[[1.5]], B=[[1.0]], C=[[1.0]], dt=0.02)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's overflow warning would raise here
        y = model.simulate(np.ones((3000, 1)))
    assert np.isfinite(y[:100]).all() and not np.isfinite(y[-1]).all()
