"""Model files: HDF5 (with provenance and units), JSON and MATLAB ``.mat``.

HDF5 layout (root attributes ``format``, ``version``, ``dt`` with ``dt_unit = "s"``,
``provenance`` as a JSON string, channel names/units as JSON lists): one dataset per matrix
``A, B, C, D, K`` (and ``noise_cov`` when known), each with attributes ``row_units`` and
``col_units`` (JSON lists; state coordinates are ``"state"``).
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import scipy.io

from sysid.errors import ModelFileError

if TYPE_CHECKING:
    from sysid.model import StateSpaceModel

__all__ = ["load", "save"]

log = logging.getLogger(__name__)

_H5 = (".h5", ".hdf5")


def _units(model: StateSpaceModel) -> dict[str, tuple[list[str], list[str]]]:
    n = model.n_states
    st = ["state"] * n
    uu = [u or "1" for u in model.input_units]
    yu = [u or "1" for u in model.output_units]
    return {"A": (st, st), "B": (st, uu), "C": (yu, st), "D": (yu, uu), "K": (st, yu),
            "noise_cov": (yu, yu)}


def save(model: StateSpaceModel, path: Path) -> Path:
    """Write ``model`` to ``path`` in the format its suffix names."""
    suffix = path.suffix.lower()
    if suffix in _H5:
        _save_h5(model, path)
    elif suffix == ".json":
        path.write_text(model.to_json())
    elif suffix == ".mat":
        _save_mat(model, path)
    else:
        raise ModelFileError(f"model file suffix {suffix!r} is unknown; use .h5, .json or .mat")
    log.info("saved %d-state model to %s", model.n_states, path)
    return path


def load(path: Path) -> StateSpaceModel:
    """Read a model file written by :func:`save`."""
    from sysid.model import StateSpaceModel

    if not path.is_file():
        raise ModelFileError(f"model file {str(path)!r} does not exist; check the path")
    suffix = path.suffix.lower()
    try:
        if suffix in _H5:
            return StateSpaceModel.from_dict(_load_h5(path))
        if suffix == ".json":
            return StateSpaceModel.from_dict(json.loads(path.read_text()))
        if suffix == ".mat":
            return StateSpaceModel.from_dict(_load_mat(path))
    except (OSError, KeyError, json.JSONDecodeError, scipy.io.matlab.MatReadError) as exc:
        raise ModelFileError(f"{str(path)!r} is not a readable sysid model ({exc}); "
                             "pass a file written by model.save") from exc
    raise ModelFileError(f"model file suffix {suffix!r} is unknown; use .h5, .json or .mat")


def _save_h5(model: StateSpaceModel, path: Path) -> None:
    import h5py

    d = model.to_dict()
    units = _units(model)
    with h5py.File(path, "w") as f:
        f.attrs["format"] = d["format"]
        f.attrs["version"] = d["version"]
        f.attrs["dt"] = model.dt
        f.attrs["dt_unit"] = "s"
        f.attrs["provenance"] = json.dumps(d["provenance"])
        for attr in ("input_names", "output_names", "input_units", "output_units"):
            f.attrs[attr] = json.dumps(d[attr])
        for name in ("A", "B", "C", "D", "K", "noise_cov"):
            value = getattr(model, name)
            if value is None:
                continue
            ds = f.create_dataset(name, data=np.asarray(value))
            ds.attrs["row_units"] = json.dumps(units[name][0])
            ds.attrs["col_units"] = json.dumps(units[name][1])


def _load_h5(path: Path) -> dict:
    import h5py

    with h5py.File(path, "r") as f:
        d: dict = {"format": str(f.attrs["format"]), "version": int(f.attrs["version"]),
                   "dt": float(f.attrs["dt"]),
                   "provenance": json.loads(f.attrs["provenance"])}
        for attr in ("input_names", "output_names", "input_units", "output_units"):
            d[attr] = json.loads(f.attrs[attr])
        for name in ("A", "B", "C", "D", "K"):
            d[name] = f[name][()]
        d["noise_cov"] = f["noise_cov"][()] if "noise_cov" in f else None
    return d


def _save_mat(model: StateSpaceModel, path: Path) -> None:
    from scipy.io import savemat

    d = model.to_dict()
    mdict = {name: np.asarray(getattr(model, name)) for name in ("A", "B", "C", "D", "K")}
    if model.noise_cov is not None:
        mdict["noise_cov"] = model.noise_cov
    mdict.update(Ts=model.dt, Ts_unit="s", format=d["format"], version=d["version"],
                 InputName=np.array(d["input_names"], dtype=object),
                 OutputName=np.array(d["output_names"], dtype=object),
                 InputUnit=np.array(d["input_units"], dtype=object),
                 OutputUnit=np.array(d["output_units"], dtype=object),
                 provenance=json.dumps(d["provenance"]))
    savemat(path, mdict)


def _load_mat(path: Path) -> dict:
    from scipy.io import loadmat

    m = loadmat(path, squeeze_me=False)

    def strings(key: str) -> list[str]:
        return [str(np.asarray(s).reshape(-1)[0]) if np.asarray(s).size else ""
                for s in np.asarray(m[key]).reshape(-1)]

    d: dict = {"format": str(m["format"][0]), "version": int(np.asarray(m["version"]).item()),
               "dt": float(np.asarray(m["Ts"]).item()),
               "provenance": json.loads(str(m["provenance"][0]))}
    for name in ("A", "B", "C", "D", "K"):
        d[name] = np.asarray(m[name], dtype=float)
    d["noise_cov"] = np.asarray(m["noise_cov"], dtype=float) if "noise_cov" in m else None
    d["input_names"], d["output_names"] = strings("InputName"), strings("OutputName")
    d["input_units"], d["output_units"] = strings("InputUnit"), strings("OutputUnit")
    return d
