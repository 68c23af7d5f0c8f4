"""What the model-file tests (``tests/sysid/test_model_io*.py``) share: the model they save and
the check that a file is refused in one line, by the library and by the CLI.

The tests by subject: ``test_model_io.py`` round trips, damaged and foreign files and the caps
``save`` keeps to what ``load`` reads; ``test_model_io_hdf5.py``, ``test_model_io_json.py`` and
``test_model_io_mat.py`` files crafted in each format.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from sysid.cli import main
from sysid.errors import ModelFileError
from sysid.model import StateSpaceModel
from sysid.model_io import load


def sample_model(*, noise: bool = True) -> StateSpaceModel:
    """A two-state model with names, units, provenance and (unless ``noise=False``) a noise
    covariance: what every test here saves, crafts and reads back."""
    return StateSpaceModel(
        A=np.array([[0.9, 0.1], [0.0, 0.7]]) + 1e-17, B=np.array([[1.0], [0.5]]),
        C=np.array([[1.0, 0.0]]), D=np.array([[0.25]]), K=np.array([[0.3], [0.1 / 3]]), dt=0.01,
        input_names=("thrust",), output_names=("z",), input_units=("N",), output_units=("m",),
        noise_cov=np.array([[2.0 / 3]]) if noise else None,
        provenance={"method": "iem", "order": 2, "data": [{"file": "a.h5", "n": 3}]})


def refused(path: Path, match: str) -> str:
    """The one-line library error and the one-line CLI error (exit 2) for ``path``."""
    with pytest.raises(ModelFileError, match=match) as err:
        load(path)
    msg = str(err.value)
    assert "\n" not in msg and str(path) in msg, msg
    assert "session" not in msg and "root:" not in msg, msg
    res = CliRunner().invoke(main, ["compare", str(path), str(path.with_name("flight.h5"))])
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    out = res.stderr.strip()
    assert out.startswith("error: ") and "\n" not in out and res.stdout == "", res.output
    assert "Traceback" not in res.output and "root:" not in res.output, res.output
    return msg
