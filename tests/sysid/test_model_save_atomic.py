"""A model file is whole or absent: ``sysid.model_io.save`` writes beside the target and renames.

Known truth: the model written before (read back equal), and the folder's listing."""

from __future__ import annotations

import os

import numpy as np
import pytest

from sysid import model_io
from sysid.model import StateSpaceModel
from sysid.model_io import load, save


def _model(gain: float) -> StateSpaceModel:
    return StateSpaceModel(A=np.array([[0.9]]), B=np.array([[gain]]), C=np.array([[1.0]]),
                           D=np.zeros((1, 1)), dt=0.02, input_names=("u",),
                           output_names=("y",))


@pytest.mark.parametrize("suffix", [".h5", ".json", ".mat"])
def test_an_interrupted_save_leaves_the_old_model_as_it_was(tmp_path, monkeypatch, suffix):
    path = tmp_path / f"model{suffix}"
    save(_model(1.0), path)
    before = path.read_bytes()
    writer = {".h5": "_save_h5", ".json": "_save_json", ".mat": "_save_mat"}[suffix]
    real = getattr(model_io, writer)

    def interrupted(model, target, *, into):
        real(model, target, into=into)  # all of it written, then Ctrl-C before the rename
        with open(into, "r+b") as fh:
            fh.truncate(os.path.getsize(into) // 2)
        raise KeyboardInterrupt

    monkeypatch.setattr(model_io, writer, interrupted)
    with pytest.raises(KeyboardInterrupt):
        save(_model(2.0), path)
    assert path.read_bytes() == before and load(path).B[0, 0] == 1.0
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]  # no part file left
    monkeypatch.setattr(model_io, writer, real)
    save(_model(2.0), path)  # and replaced once complete
    assert load(path).B[0, 0] == 2.0 and sorted(p.name for p in tmp_path.iterdir()) == [path.name]
