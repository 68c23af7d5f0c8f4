"""Model files: HDF5 (with provenance and units), JSON and MATLAB ``.mat``.

HDF5 layout (root attributes ``format``, ``version``, ``dt`` with ``dt_unit = "s"``,
``provenance`` as a JSON string, channel names/units as JSON lists): one dataset per matrix
``A, B, C, D, K`` (and ``noise_cov`` when known), each with attributes ``row_units`` and
``col_units`` (JSON lists; state coordinates are ``"state"``).
"""

from __future__ import annotations

import json
import logging
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import scipy.io

from sysid.errors import ModelFileError, SysIdError

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
    """Write ``model`` to ``path`` in the format its suffix names (one-line
    :class:`ModelFileError` when it cannot be written)."""
    suffix = path.suffix.lower()
    writers = {**dict.fromkeys(_H5, _save_h5), ".mat": _save_mat,
               ".json": lambda m, p: p.write_text(m.to_json())}
    if suffix not in writers:
        raise ModelFileError(f"model file suffix {suffix!r} is unknown; use .h5, .json or .mat")
    if not path.parent.is_dir():
        raise ModelFileError(f"cannot write model file {str(path)!r}: folder "
                             f"{str(path.parent)!r} does not exist; create it first")
    try:
        writers[suffix](model, path)
    except OSError as exc:
        raise ModelFileError(f"cannot write model file {str(path)!r}: "
                             f"{_os_reason(exc)}") from None
    log.info("saved %d-state model to %s", model.n_states, path)
    return path


def _os_reason(exc: OSError) -> str:
    """A plain reason for an OS error; h5py's text carries internal flags, so its errno or its
    ``error message = '...'`` part is used."""
    if exc.errno:
        return os.strerror(exc.errno)
    text = str(exc)
    found = re.search(r"error message = '([^']*)'", text)
    if found:
        return found.group(1)
    return text.splitlines()[0] if text else type(exc).__name__


def load(path: Path) -> StateSpaceModel:
    """Read a model file written by :func:`save`."""
    from sysid.model import FORMAT, StateSpaceModel

    if path.is_dir():
        raise ModelFileError(f"model file {str(path)!r} is a folder; pass a model file "
                             "(.h5, .json or .mat)")
    if not path.is_file():
        raise ModelFileError(f"model file {str(path)!r} does not exist; check the path")
    suffix = path.suffix.lower()
    readers = {**dict.fromkeys(_H5, _load_h5), ".mat": _load_mat,
               ".json": lambda p: json.loads(p.read_text())}
    if suffix not in readers:
        raise ModelFileError(f"model file suffix {suffix!r} is unknown; use .h5, .json or .mat")
    not_model = (f"{str(path)!r} is not a sysid model file; pass a file written by "
                 "`sysid identify --out` or model.save")
    try:
        d = readers[suffix](path)
        if not isinstance(d, dict) or d.get("format") != FORMAT:
            fmt = d.get("format") if isinstance(d, dict) else None
            raise ModelFileError(not_model + ("" if fmt is None else f" (its format is {fmt!r},"
                                              f" not {FORMAT!r})"))
        return StateSpaceModel.from_dict(d)
    except SysIdError:
        raise
    except KeyError as exc:
        raise ModelFileError(f"{not_model} (no {exc})") from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError, scipy.io.matlab.MatReadError,
            IndexError, TypeError, ValueError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ModelFileError(f"{str(path)!r} is not a readable sysid model ({reason}); "
                             "pass a file written by model.save") from exc


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
        if "format" not in f.attrs:  # e.g. a session file
            return {}
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
    with open(path, "wb") as fh:  # opened here so an OS error keeps its errno
        savemat(fh, mdict)


def _load_mat(path: Path) -> dict:
    from scipy.io import loadmat

    m = loadmat(path, squeeze_me=False)
    if "format" not in m:
        return {}

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
