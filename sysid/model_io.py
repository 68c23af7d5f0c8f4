"""Model files: HDF5 (with provenance and units), JSON and MATLAB ``.mat``.

HDF5 layout (root attributes ``format``, ``version``, ``dt`` with ``dt_unit = "s"``,
``provenance`` as a JSON string, channel names/units as JSON lists): one dataset per matrix
``A, B, C, D, K`` (and ``noise_cov`` when known), each with attributes ``row_units`` and
``col_units`` (JSON lists; state coordinates are ``"state"``). MAT files hold the same matrices
under the same names, ``Ts`` and the names, units and provenance; ``noise_cov`` is the
innovation covariance that goes with K (:mod:`sysid.innovation_cov`), what MATLAB's ``idss``
takes as ``NoiseVariance``: ``idss(A, B, C, D, K, zeros(n, 1), Ts, "NoiseVariance",
noise_cov)``.

:func:`save` refuses, in one line and before writing, a model that :func:`load` would refuse
(more than :data:`MAX_DIMENSION` states, inputs or outputs; a ``.mat`` or ``.json`` file over
:data:`MAX_FILE_BYTES`; in ``.h5`` or ``.mat``, a text over :data:`MAX_TEXT_BYTES`), naming the
limit and the format that holds it: the caps bound what an untrusted file costs to read, so they
are not raised to the largest model the formats can hold. :data:`MAX_DIMENSION` (500) is 2.5
times the largest order live identification takes and over ten times what order selection
sweeps (:data:`sysid.growth.MAX_ORDER`); ``sysid identify --order`` refuses more. A 2000-state
model took ``sysid compare`` over 25 s and a JSON export of hundreds of MB; a 500-state model
with a few channels is 2 MB as ``.mat``, about 6 MB as JSON, and compares in seconds.

**Model files come from anywhere**, so :func:`load` reads each format into one plain dict
and checks it before a model is made: the format name; a version from 1 to
:data:`~sysid.model.FORMAT_VERSION` (none is refused); every matrix present, real, finite,
two-dimensional, at most :data:`MAX_DIMENSION` a side and of the shape the others imply
(``A (n, n)``, ``B (n, m)``, ``C (l, n)``, ``D (l, m)``, ``K (n, l)``, ``noise_cov (l, l)``);
``dt`` positive seconds; names and units lists of text, one per channel; provenance an object.
HDF5 is opened through the session reader's guard (:mod:`cfsession.guard`: no external storage,
which reads other files or blocks on a FIFO, no links, virtual datasets or sizes the file cannot
hold), each matrix's type and shape checked before it is read. JSON and MAT are read once, from
a regular file of at most :data:`MAX_FILE_BYTES`; a MAT file must be what :func:`save` writes:
MATLAB 5, uncompressed (an element may inflate a thousandfold), only numbers, text and cells of
those (scipy's reader recurses in C through nested cells: 9 MB of them crash the interpreter).
Anything refused is one :class:`~sysid.errors.ModelFileError` line.
"""

from __future__ import annotations

import contextlib
import io
import json
import logging
import math
import os
import re
import stat
from collections import Counter
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from sysid.errors import ModelFileError, first_line
from sysid.mat_guard import Limits, check_mat

if TYPE_CHECKING:
    from sysid.model import StateSpaceModel

__all__ = ["MAX_DIMENSION", "MAX_FILE_BYTES", "check_not_a_session", "holds_a_session", "load",
           "save"]

log = logging.getLogger(__name__)

_H5 = (".h5", ".hdf5")
MAX_DIMENSION = 500
"""Most states, inputs or outputs a model file may have, and a model :func:`save` writes (the
module docstring says why 500)."""
MAX_FILE_BYTES = 128 << 20
"""Largest JSON or MAT model file read (a model of 500 states, inputs and outputs is about
36 MB as JSON)."""
MAX_TEXT_BYTES = 1 << 20
"""Largest text of a MAT model (its provenance JSON), as an HDF5 model's attributes."""
MAX_JSON_CONTAINERS = 1_000_000
"""Most JSON arrays and objects in a JSON model file (a 500-state model has about 1 500)."""
_SHAPES = {"A": "nn", "B": "nm", "C": "ln", "D": "lm", "K": "nl", "noise_cov": "ll"}
_LABELS = {"input_names": "m", "output_names": "l", "input_units": "m", "output_units": "l"}
_COUNTS = {"n": "states", "m": "inputs", "l": "outputs"}
_KINDS = {"b": "true/false values", "S": "text", "U": "text", "O": "objects", "V": "records"}


def _units(model: StateSpaceModel) -> dict[str, tuple[list[str], list[str]]]:
    n = model.n_states
    st = ["state"] * n
    uu = [u or "1" for u in model.input_units]
    yu = [u or "1" for u in model.output_units]
    return {"A": (st, st), "B": (st, uu), "C": (yu, st), "D": (yu, uu), "K": (st, yu),
            "noise_cov": (yu, yu)}


def save(model: StateSpaceModel, path: str | os.PathLike[str]) -> Path:
    """Write ``model`` to ``path`` in the format its suffix names (one-line
    :class:`ModelFileError` when it cannot be written). It is written beside ``path`` and
    renamed onto it when complete: a model file is whole or absent (Ctrl-C, a full disk), and
    one it replaces stays as it was until then. A missing folder of ``path`` is made."""
    path = Path(path)
    suffix = path.suffix.lower()
    writers = {**dict.fromkeys(_H5, _save_h5), ".mat": _save_mat, ".json": _save_json}
    if suffix not in writers:
        raise ModelFileError(f"model file suffix {suffix!r} is unknown; use .h5, .json or .mat")
    for count, what in ((model.n_states, "states"), (model.n_inputs, "inputs"),
                        (model.n_outputs, "outputs")):
        if count > MAX_DIMENSION:
            raise ModelFileError(f"cannot write model file {str(path)!r}: {count} {what}, more "
                                 f"than the {MAX_DIMENSION} that load reads (MAX_DIMENSION)")
    above = next((p for p in path.parents if p.exists()), None)  # made below if missing
    if above is not None and not above.is_dir():
        raise ModelFileError(f"cannot write model file {str(path)!r}: {str(above)!r} is a "
                             "file, not a folder")
    check_not_a_session(path)
    part = path.with_name(f".{path.name}.{os.getpid()}.part")  # whole or not at all
    try:
        path.parent.mkdir(parents=True, exist_ok=True)  # as a session's writer makes its folder
        writers[suffix](model, path, into=part)
        os.replace(part, path)
    except OSError as exc:
        raise ModelFileError(f"cannot write model file {str(path)!r}: "
                             f"{_os_reason(exc)}") from None
    finally:
        with contextlib.suppress(OSError):  # no folder to hold it: the error above says why
            part.unlink(missing_ok=True)
    log.info("saved %d-state model to %s", model.n_states, path)
    return path


def check_not_a_session(path: str | os.PathLike[str]) -> None:
    """One-line :class:`ModelFileError` when ``path`` holds a flight session: a model never
    replaces recorded data (``--force`` replaced a read-only session with a model)."""
    if holds_a_session(Path(path)):
        raise ModelFileError(f"cannot write model file {str(path)!r}: it holds a recorded flight "
                             "session, which a model never replaces (not even with --force); "
                             "choose another name")


def holds_a_session(path: Path) -> bool:
    """Whether ``path`` is a flight session file, read as an untrusted file: an HDF5 file whose
    root ``schema`` attribute (read through the session guard's size checks) names the session
    schema, or an HDF5 file the guard will not open (damaged, cut short, too large, unreadable)
    whose first 64 KiB hold that name: a model saved over it would lose a recorded flight."""
    from cfsession.guard import HDF5_SIGNATURE, open_untrusted, read_attrs
    from cfsession.schema import SCHEMA_NAME

    try:
        if not path.is_file():
            return False
        with path.open("rb") as fh:
            head = fh.read(_SESSION_SNIFF_BYTES)
    except OSError:
        return False  # nothing this process can read: nothing it could lose by writing
    if not head.startswith(HDF5_SIGNATURE):
        return False
    try:
        f, _ = open_untrusted(path)
        with f:
            value = read_attrs(f, where=str(path), problems=[], kind="file").get("schema")
    except Exception:  # best effort: a file the guard refuses (or h5py fails on) is sniffed
        return SCHEMA_NAME.encode() in head
    if isinstance(value, bytes):
        value = value.decode("utf-8", "replace")
    return isinstance(value, str) and value == SCHEMA_NAME


#: Bytes of an unopenable HDF5 file searched for the session schema's name.
_SESSION_SNIFF_BYTES = 64 * 1024


def _os_reason(exc: OSError) -> str:
    """A plain reason for an OS error; h5py's text carries internal flags, so its errno or its
    ``error message = '...'`` part is used."""
    if exc.errno:
        return os.strerror(exc.errno)
    text = str(exc)
    found = re.search(r"error message = '([^']*)'", text)
    if found:
        return found.group(1)
    return first_line(exc)


# ------------------------------------------------------------------------------- loading
def load(path: str | os.PathLike[str]) -> StateSpaceModel:
    """Read a model file written by :func:`save`; anything else is one
    :class:`ModelFileError` line (see the module docstring)."""
    from sysid.model import StateSpaceModel

    path = Path(path)
    if path.is_dir():
        raise ModelFileError(f"model file {str(path)!r} is a folder; pass a model file "
                             "(.h5, .json or .mat)")
    if not path.exists():
        raise ModelFileError(f"model file {str(path)!r} does not exist; check the path")
    if not path.is_file():
        raise ModelFileError(f"model file {str(path)!r} is not a regular file (a device, FIFO "
                             "or socket); pass a model file (.h5, .json or .mat)")
    suffix = path.suffix.lower()
    readers = {**dict.fromkeys(_H5, _load_h5), ".mat": _load_mat, ".json": _load_json}
    if suffix not in readers:
        raise ModelFileError(f"model file suffix {suffix!r} is unknown; use .h5, .json or .mat")
    try:
        return StateSpaceModel(**_checked(readers[suffix](path), path=path))
    except ModelFileError:
        raise
    except Exception as exc:  # whatever a crafted file makes a parser raise: never a traceback
        log.debug("reading model file %s", path, exc_info=True)
        from cfsession.guard import short_error

        raise _unreadable(path, short_error(exc)) from None


def _unreadable(path: Path, reason: str) -> ModelFileError:
    return ModelFileError(f"{str(path)!r} is not a readable sysid model ({reason}); pass a "
                          "file written by `sysid identify --out` or model.save")


def _brief(value: object) -> str:
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _scalar(value: object) -> object:
    """A one-element array (MAT, HDF5) or numpy scalar as a Python value; else ``value``."""
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(-1)[0]
    if isinstance(value, bytes):
        return value.decode()
    return value.item() if isinstance(value, np.generic) else value


def _checked(d: object, *, path: Path) -> dict[str, Any]:
    """The keyword arguments of :class:`~sysid.model.StateSpaceModel` that ``d`` (a file's
    contents) holds, checked as the module docstring says; else :class:`ModelFileError`."""
    from sysid.model import FORMAT, FORMAT_VERSION

    fmt = _scalar(d.get("format")) if isinstance(d, dict) else None
    if (not isinstance(d, dict) or not isinstance(fmt, str) or fmt != FORMAT) and (
            holds_a_session(path)):  # the arguments swapped: `sysid compare SESSION MODEL`
        raise ModelFileError(f"{str(path)!r} is a flight session, not a sysid model file: make "
                             f"a model from it with `sysid identify {path} --out model.h5` and "
                             "pass that")
    if not isinstance(d, dict) or not isinstance(fmt, str) or fmt != FORMAT:
        raise ModelFileError(f"{str(path)!r} is not a sysid model file; pass a file written by "
                             "`sysid identify --out` or model.save" +
                             ("" if fmt is None else f" (its format is {_brief(fmt)}, "
                              f"not {FORMAT!r})"))
    version = _scalar(d.get("version"))
    if isinstance(version, float) and version.is_integer():
        version = int(version)  # MATLAB keeps numbers as double
    if type(version) is not int or not 1 <= version <= FORMAT_VERSION:
        if type(version) is int and version > FORMAT_VERSION:
            raise ModelFileError(f"{str(path)!r}: model format version {version} is newer than "
                                 f"{FORMAT_VERSION}; upgrade sysid to read it")
        got = "no format version" if version is None else f"format version {_brief(version)}"
        raise _unreadable(path, f"{got}; this sysid reads versions 1 to {FORMAT_VERSION}")
    missing = [k for k in (*"ABCDK", "dt", *_LABELS, "provenance") if k not in d]
    if missing:
        raise _unreadable(path, f"no {', '.join(missing)}")
    mats = {name: _matrix(name, d[name], path=path) for name in _SHAPES
            if d.get(name) is not None}
    labels: dict[str, tuple[str, ...]] = {}
    for key in _LABELS:
        if not isinstance(d[key], list | tuple) or not all(isinstance(s, str) for s in d[key]):
            raise _unreadable(path, f"{key} is {_brief(d[key])}, not a list of text")
        labels[key] = tuple(d[key])
    sizes = _sizes(mats, labels)
    dims = ", ".join(f"{v} {_COUNTS[k]}" for k, v in sizes.items())
    for name, arr in mats.items():
        want = tuple(sizes[k] for k in _SHAPES[name])
        if arr.ndim == 1 and 0 in want:
            mats[name] = arr = arr.reshape(want)
        if arr.shape != want:
            raise _unreadable(path, f"matrix {name!r} has shape {arr.shape}; it must be "
                              f"({', '.join(_SHAPES[name])}) = {want} ({dims})")
    for key, k in _LABELS.items():
        if len(labels[key]) != sizes[k]:
            raise _unreadable(path, f"{key} has {len(labels[key])} entries; the model has "
                              f"{sizes[k]} {_COUNTS[k]} ({dims})")
    dt, unit = _scalar(d["dt"]), _scalar(d.get("dt_unit", "s"))
    if isinstance(dt, bool) or not isinstance(dt, int | float) or not math.isfinite(dt) or dt <= 0:
        raise _unreadable(path, f"dt is {_brief(dt)}; it must be the sample period in seconds")
    if not isinstance(unit, str) or unit != "s":
        raise _unreadable(path, f"dt_unit is {_brief(unit)}; sysid models keep dt in seconds")
    if not isinstance(d["provenance"], dict):
        raise _unreadable(path, f"provenance is {_brief(d['provenance'])}, not a JSON object")
    return {**mats, **labels, "dt": float(dt), "provenance": d["provenance"]}


def _sizes(mats: dict[str, np.ndarray], labels: dict[str, tuple[str, ...]]) -> dict[str, int]:
    """States ``n``, inputs ``m`` and outputs ``l``: for each, the size most matrices and
    label lists agree on (so an error names the one that differs; a tie goes to the first of
    A, B, C, D, K)."""
    votes: dict[str, list[int]] = {"n": [], "m": [], "l": []}
    for name, arr in mats.items():
        if arr.ndim == 2:  # JSON writes an empty matrix as []
            for k, size in zip(_SHAPES[name], arr.shape, strict=True):
                votes[k].append(size)
    for key, k in _LABELS.items():
        votes[k].append(len(labels[key]))
    return {k: Counter(v).most_common(1)[0][0] for k, v in votes.items()}


def _matrix_type(name: str, *, dtype: np.dtype, shape: tuple[int, ...], path: Path) -> None:
    """Refuse a matrix that is not real numbers, two-dimensional (or an empty list) and at
    most :data:`MAX_DIMENSION` on a side; HDF5 calls this before reading the data."""
    if dtype.kind == "c":
        raise _unreadable(path, f"matrix {name!r} is complex ({dtype}); a sysid model's "
                          "matrices are real")
    if dtype.kind not in "iuf" or dtype.subdtype is not None:
        raise _unreadable(path, f"matrix {name!r} holds {_KINDS.get(dtype.kind, dtype)}, "
                          "not numbers")
    if len(shape) != 2 and shape != (0,):
        raise _unreadable(path, f"matrix {name!r} has shape {shape}; it must be "
                          "two-dimensional")
    if max(shape, default=0) > MAX_DIMENSION:
        raise _unreadable(path, f"matrix {name!r} has shape {shape}; a sysid model file has at "
                          f"most {MAX_DIMENSION} states, inputs and outputs (MAX_DIMENSION)")


def _matrix(name: str, value: object, *, path: Path) -> np.ndarray:
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError):  # ragged lists
        raise _unreadable(path, f"matrix {name!r} is not a table of numbers") from None
    _matrix_type(name, dtype=arr.dtype, shape=arr.shape, path=path)
    arr = arr.astype(float)
    if not np.isfinite(arr).all():
        raise _unreadable(path, f"matrix {name!r} contains NaN or inf")
    return arr


def _read_bounded(path: Path) -> bytes:
    """The bytes of a regular file of at most :data:`MAX_FILE_BYTES` (a FIFO is refused
    without blocking)."""
    fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
    with os.fdopen(fd, "rb") as fh:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise _unreadable(path, "not a regular file")
        data = fh.read(MAX_FILE_BYTES + 1)
    if len(data) > MAX_FILE_BYTES:
        raise _unreadable(path, f"larger than {MAX_FILE_BYTES} bytes, more than a model takes")
    return data


def _load_json(path: Path) -> object:
    data = _read_bounded(path)
    # Python builds an object of about 60 bytes for each "[]": a file of them would take 20
    # times its size in memory. A 500-state model has about 1 500 arrays.
    containers = data.count(b"[") + data.count(b"{")
    if containers > MAX_JSON_CONTAINERS:
        raise _unreadable(path, f"{containers} JSON arrays and objects, more than a model has "
                                f"({MAX_JSON_CONTAINERS})")
    return json.loads(data)


def _load_h5(path: Path) -> dict[str, Any]:
    """The raw contents of an HDF5 model, read through :mod:`cfsession.guard` (see the module
    docstring): every object is checked before it is read."""
    import h5py

    from cfsession.errors import SessionError
    from cfsession.guard import check_storage, file_size, hard_links, open_untrusted, read_attrs

    where, kind = str(path), "sysid model"
    try:
        f, _clean = open_untrusted(path, kind=kind)
        with f:
            problems: list[str] = []
            attrs = read_attrs(f, where=where, problems=problems, kind=kind)
            _refuse_unread(problems, [n for n in f.attrs if n not in attrs], path=path,
                           where=where)
            if "format" not in attrs:  # e.g. a session file
                return {}
            for problem in problems:  # an attribute no model has: the model reads without it
                log.warning("%s; a sysid model does not use it", problem)
            d: dict[str, Any] = {k: _scalar(v) for k, v in attrs.items()
                                 if k in ("format", "version", "dt", "dt_unit")}
            for key in ("provenance", *_LABELS):
                if key in attrs:
                    d[key] = json.loads(_scalar(attrs[key]))
            size = file_size(f, path)
            for name, obj in hard_links(f, where=where, kind=kind):
                if name not in _SHAPES:
                    continue
                if not isinstance(obj, h5py.Dataset):
                    raise _unreadable(path, f"matrix {name!r} is a group, not a dataset")
                check_storage(obj, where=f"matrix {name!r}", file_size=size)
                _matrix_type(name, dtype=obj.dtype, shape=obj.shape or (), path=path)
                d[name] = obj[()]
    except SessionError as exc:
        raise _unreadable(path, str(exc).removeprefix(f"{where}: ")) from None
    return d


_MODEL_ATTRS = frozenset({"format", "version", "dt", "dt_unit", "provenance", *_LABELS})
"""The root attributes of an HDF5 model that :func:`load` reads; any other is not used."""


def _refuse_unread(problems: list[str], left_out: list[str], *, path: Path, where: str) -> None:
    """One line for the first attribute in ``left_out`` (those the guard did not read: too
    large, of another type, unreadable) that a model needs; the guard's ``problems`` say
    "skipped", but a model is not read without one of these."""
    for name in (n for n in left_out if n in _MODEL_ATTRS):
        said = next((p for p in problems if f"attribute {name!r} " in p), "")
        # "WHERE: attribute 'X' skipped (WHY)" or "... unreadable (WHY)"
        why = said.partition(f"attribute {name!r} ")[2].partition(" (")[2].removesuffix(")")
        raise _unreadable(path, f"attribute {name!r} cannot be read: {why or 'unknown'}")


def _within(path: Path, what: str, size: int, limit: tuple[int, str], instead: str) -> None:
    """Refuse to write what :func:`load` would refuse: ``size`` bytes over ``limit`` (its value
    and name)."""
    if size > limit[0]:
        raise ModelFileError(f"cannot write model file {str(path)!r}: {what} would be {size} "
                             f"bytes, more than the {limit[0]} that load reads ({limit[1]}); "
                             f"save the model as {instead}")


def _save_json(model: StateSpaceModel, path: Path, *, into: Path) -> None:
    data = model.to_json().encode()
    _within(path, "the JSON file", len(data), (MAX_FILE_BYTES, "MAX_FILE_BYTES"), ".h5")
    into.write_bytes(data)


def _save_h5(model: StateSpaceModel, path: Path, *, into: Path) -> None:
    import h5py

    d = model.to_dict()
    units = _units(model)
    texts = {"provenance": json.dumps(d["provenance"]),
             **{attr: json.dumps(d[attr]) for attr in _LABELS}}
    for attr, text in texts.items():
        _within(path, f"its {attr} text", len(text.encode()),
                 (MAX_TEXT_BYTES, "MAX_TEXT_BYTES"), ".json")
    # built in memory, then written by plain file I/O: a full disk is then an OSError of
    # that write, where HDF5 failing inside its own writes crashed in its cleanup (exit 139)
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs["format"] = d["format"]
        f.attrs["version"] = d["version"]
        f.attrs["dt"] = model.dt
        f.attrs["dt_unit"] = "s"
        for attr, text in texts.items():
            f.attrs[attr] = text
        for name in ("A", "B", "C", "D", "K", "noise_cov"):
            value = getattr(model, name)
            if value is None:
                continue
            ds = f.create_dataset(name, data=np.asarray(value))
            ds.attrs["row_units"] = json.dumps(units[name][0])
            ds.attrs["col_units"] = json.dumps(units[name][1])
    into.write_bytes(buffer.getvalue())



def _save_mat(model: StateSpaceModel, path: Path, *, into: Path) -> None:
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
    _within(path, "its provenance text", len(mdict["provenance"].encode()),
             (MAX_TEXT_BYTES, "MAX_TEXT_BYTES"), ".json")
    buf = io.BytesIO()
    savemat(buf, mdict)
    _within(path, "the .mat file", buf.tell(), (MAX_FILE_BYTES, "MAX_FILE_BYTES"), ".h5")
    with open(into, "wb") as fh:  # opened here so an OS error keeps its errno
        fh.write(buf.getbuffer())


def _load_mat(path: Path) -> dict[str, Any]:
    from scipy.io import loadmat

    data = _read_bounded(path)
    check_mat(data, limits=Limits(values=MAX_DIMENSION ** 2, side=MAX_DIMENSION,
                                  cells=MAX_DIMENSION,
                                  text_bytes=MAX_TEXT_BYTES))
    m = loadmat(io.BytesIO(data), squeeze_me=False)
    if "format" not in m:
        return {}

    def strings(key: str) -> object:
        """A cell of texts as a list; anything else as is (refused by :func:`_checked`)."""
        cells = np.asarray(m[key]).reshape(-1)
        texts = [np.asarray(s).reshape(-1) for s in cells] if cells.dtype.kind == "O" else []
        if len(texts) != cells.size or any(t.size and t.dtype.kind != "U" for t in texts):
            return m[key]
        return [str(t[0]) if t.size else "" for t in texts]

    d: dict[str, Any] = {"format": m["format"], "version": m.get("version")}
    for key, name in (("dt", "Ts"), ("dt_unit", "Ts_unit"), *((k, k) for k in _SHAPES)):
        if name in m:
            d[key] = m[name]
    if "provenance" in m:
        d["provenance"] = json.loads(_scalar(m["provenance"]))
    for key, name in (("input_names", "InputName"), ("output_names", "OutputName"),
                      ("input_units", "InputUnit"), ("output_units", "OutputUnit")):
        if name in m:
            d[key] = strings(name)
    return d
