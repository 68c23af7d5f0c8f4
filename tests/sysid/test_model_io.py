"""sysid/model_io.py: every format round-trips a model; a damaged or foreign file is one line."""
from __future__ import annotations

import numpy as np
import pytest

from sysid.errors import ModelFileError
from sysid.model import StateSpaceModel
from sysid.model_io import load, save


def _model() -> StateSpaceModel:
    return StateSpaceModel(
        A=np.array([[0.9, 0.1], [0.0, 0.7]]), B=np.array([[1.0], [0.5]]),
        C=np.array([[1.0, 0.0]]), D=np.array([[0.25]]), K=np.array([[0.3], [0.1]]), dt=0.01,
        input_names=("thrust",), output_names=("z",), input_units=("N",), output_units=("m",),
        provenance={"method": "iem", "order": 2})


@pytest.mark.parametrize("suffix", [".h5", ".json", ".mat"])
def test_round_trip(tmp_path, suffix):
    m = _model()
    back = load(save(m, tmp_path / f"m{suffix}"))
    for name in "ABCDK":
        np.testing.assert_allclose(getattr(back, name), getattr(m, name))
    assert back.dt == m.dt
    assert back.output_names == ("z",) and back.input_units == ("N",)
    assert back.provenance["method"] == "iem"


@pytest.mark.parametrize("suffix", [".h5", ".json", ".mat"])
def test_damaged_file_is_one_line(tmp_path, suffix):
    path = save(_model(), tmp_path / f"m{suffix}")
    path.write_bytes(path.read_bytes()[:40])
    with pytest.raises(ModelFileError) as err:
        load(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_foreign_json_and_unknown_suffix(tmp_path):
    (tmp_path / "x.json").write_text('{"format": "other"}')
    with pytest.raises(ModelFileError, match="not a sysid model file"):
        load(tmp_path / "x.json")
    with pytest.raises(ModelFileError, match=r"suffix '\.txt' is unknown"):
        save(_model(), tmp_path / "m.txt")
    with pytest.raises(ModelFileError, match="does not exist"):
        save(_model(), tmp_path / "no" / "m.h5")
