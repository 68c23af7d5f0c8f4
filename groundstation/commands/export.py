"""``groundstation export SESSION --to csv|mat|parquet``: the session for pandas and MATLAB.

* ``csv``: a folder with one ``STREAM.csv`` per stream (header ``field [unit]``, values at full
  precision, text decoded as UTF-8, an event's continued text joined into one row) and
  ``metadata.json``; ``pandas.read_csv`` reads each. Two streams whose names differ only in
  case (``Motors``, ``motors``) would share a file on a case-insensitive file system (macOS,
  Windows, a FAT card): the later one's file gets ``_2``, ``_3``, ... (``motors_2.csv``), and
  ``metadata.json`` maps every stream to its file (``stream_files``).
* ``mat``: one MATLAB file holding what ``iddata`` needs, ``u`` (N x m), ``y`` (N x l), ``Ts``
  (s), ``InputName``, ``OutputName``, ``InputUnit``, ``OutputUnit``, ``ExperimentName``
  (cell arrays): the data ``sysid identify`` identifies from, with its default channels,
  window (``auto``: each excitation phase, else each airborne segment) and the logged period
  (resampled on a uniform grid, not detrended; ``--inputs``, ``--outputs``, ``--window``,
  ``--dt``). Several experiments make ``u`` and ``y`` 1 x E cell arrays, one N_e x m (N_e x l)
  matrix each, iddata's multi-experiment form. Plus every stream as ``streams.STREAM.FIELD``
  (column vectors), their units as ``units.STREAM.FIELD`` and the metadata as ``metadata`` (a
  log without the default channels or window, imported from elsewhere: every stream and no
  iddata part, with a warning, unless ``--inputs``/``--outputs``/``--window`` is given)::

      s = load('flight.mat');
      data = iddata(s.y, s.u, s.Ts, 'InputName', s.InputName, 'OutputName', s.OutputName, ...
                    'InputUnit', s.InputUnit, 'OutputUnit', s.OutputUnit, ...
                    'ExperimentName', s.ExperimentName);

* ``parquet``: a folder with one ``STREAM.parquet`` per stream (each field's unit in its
  metadata, key ``unit``; files named as for ``csv``) and the same ``metadata.json`` as
  ``csv``; needs ``pyarrow``.

Names that are no MATLAB identifier (``stateEstimate.z``) become one (``stateEstimate_z``;
ASCII, at most 63 characters, ``_2``, ``_3``, ... when that name is taken). An imported log's
``host_time`` holds the firmware's clock (it has no host's): every format names that column
``fw_time`` (``fw_time [s]``), a flown session's keep ``host_time``.
A damaged or crash-truncated session is exported as far as it reads, and each of its problems
(those ``groundstation info`` lists) is logged as a warning naming the file. Each file is
written beside its name and renamed onto it when complete (:func:`cfcommon.cli.whole_file`):
a full disk or ``ulimit -f`` leaves no file cut short, and the error names the file it stopped
at.
"""

from __future__ import annotations

import csv
import importlib
import json
import logging
import os
import re
import unicodedata
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, Literal

import click
import numpy as np

from cfcommon.cli import DEFAULT_INPUTS, DEFAULT_OUTPUTS, FiniteFloat, whole_file
from cfsession import Session, open_session, warn_problems
from groundstation.errors import GroundStationError, SessionError

__all__ = ["command", "export_csv", "export_mat", "export_parquet", "write_metadata"]

Format = Literal["csv", "mat", "parquet"]

log = logging.getLogger(__name__)


def _columns(session: Session, name: str) -> dict[str, list[Any] | np.ndarray]:
    """Every field of stream ``name``: numbers as arrays, text (bytes) decoded; an event text
    continued on following rows is joined into one row (``Session.events``)."""
    if session[name].kind == "events":
        events = session.events()
        return {"host_time": np.array([e.t for e in events], dtype=float),
                "level": [e.level for e in events], "source": [e.source for e in events],
                "text": [e.text for e in events]}
    data = session[name].data
    out: dict[str, list[Any] | np.ndarray] = {}
    for f in data.dtype.names:
        col = data[f]
        if col.dtype.kind == "S":
            out[f] = [bytes(v).decode("utf-8", errors="replace") for v in col]
        else:
            out[f] = col
    return out


#: What an imported log's ``host_time`` is exported as: it holds the firmware's seconds (the log
#: has no host clock; docs/session-format.md, "Times").
FIRMWARE_TIME = "fw_time"


def _labels(session: Session, fields: Any) -> dict[str, str]:
    """``{field: its name in the export}``: the session's own, except an imported log's
    ``host_time``, which is :data:`FIRMWARE_TIME` (named by what it holds; ``_2``, ... if a
    field already has that name). A flown session's columns keep their names."""
    fields = list(fields)
    labels = {f: f for f in fields}
    if session.imported and "host_time" in labels:
        name, k = FIRMWARE_TIME, 2
        while name in labels:
            name, k = f"{FIRMWARE_TIME}_{k}", k + 1
        labels["host_time"] = name
    return labels


def _metadata(session: Session) -> dict[str, Any]:
    return json.loads(json.dumps(dict(session.meta), default=_plain))


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, bytes):
        return value.decode("utf-8", errors="replace")
    return str(value)


def write_metadata(session: Session, folder: Path, *,
                   files: Mapping[str, str] | None = None) -> Path:
    """``folder/metadata.json``: the session's root attributes (``time_base``,
    ``source_problems``, ...) as JSON, beside the stream files of a csv or parquet export, and
    under ``stream_files`` which file holds each stream (``files``, if given)."""
    meta = folder / "metadata.json"
    content = {**_metadata(session), **({"stream_files": dict(files)} if files else {})}
    with whole_file(meta) as part:
        part.write_text(json.dumps(content, indent=1))
    return meta


def _caseless(name: str) -> str:
    """``name`` as a case-insensitive file system compares it (Unicode caseless matching: a
    macOS volume also takes composed and decomposed accents as one)."""
    return unicodedata.normalize("NFD", unicodedata.normalize("NFD", name).casefold())


_WINDOWS_DEVICES = re.compile(r"(CON|PRN|AUX|NUL|COM[0-9]|LPT[0-9])(\..*)?", re.IGNORECASE)


def _file_stem(name: str) -> str:
    """A file name every system takes for stream ``name`` (a session from elsewhere may name a
    stream anything HDF5 allows): ``< > : " / \\ | ? *`` and control characters as ``_``
    (Windows, a FAT card), no leading ``.`` (hidden), no trailing dot or space, not a Windows
    device name (``NUL`` -> ``NUL_``); at most 200 bytes (UTF-8; a file name has 255)."""
    stem = re.sub(r'[<>:"/\\|?*\x00-\x1f\x7f]', "_", name)
    stem = stem.encode()[:200].decode(errors="ignore").rstrip(". ")
    stem = "_" + stem[1:] if stem.startswith(".") else stem
    return f"{stem}_" if _WINDOWS_DEVICES.fullmatch(stem) else stem or "stream"


def _file_names(streams: Any, suffix: str) -> dict[str, str]:
    """``{stream: file name}``, names every file system takes (:func:`_file_stem`), distinct
    however it compares case (``Motors``, ``motors`` -> ``Motors.csv``, ``motors_2.csv``;
    :func:`_distinct`)."""
    stems = _distinct(streams, made=_file_stem, key=_caseless)
    return {name: f"{stem}{suffix}" for name, stem in stems.items()}


def export_csv(session: Session, folder: Path) -> list[Path]:
    """One ``STREAM.csv`` per stream (:func:`_file_names`) and ``metadata.json`` in
    ``folder``; returns the files."""
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    names = _file_names(session.streams, ".csv")
    for name, stream in session.streams.items():
        cols = _columns(session, name)
        labels = _labels(session, cols)
        header = [f"{labels[f]} [{stream.units[f]}]" if stream.units.get(f) else labels[f]
                  for f in cols]
        path = folder / names[name]
        with whole_file(path) as part, part.open("w", newline="", encoding="utf-8") as fh:
            writer = csv.writer(fh)
            writer.writerow(header)
            lists = [c.tolist() if isinstance(c, np.ndarray) else c for c in cols.values()]
            writer.writerows(zip(*lists, strict=True))
        files.append(path)
    return [*files, write_metadata(session, folder, files=names)]


_MATLAB_NAME = 63
"""MATLAB's ``namelengthmax``: savemat refuses a longer field name."""


def _identifier(name: str) -> str:
    """A MATLAB identifier for ``name`` (``stateEstimate.z`` -> ``stateEstimate_z``): ASCII
    letters, digits and ``_``, a letter first, at most 63 characters."""
    ident = re.sub(r"\W", "_", name, flags=re.ASCII)
    ident = ident if re.match(r"[A-Za-z]", ident) else f"f_{ident}"
    return ident[:_MATLAB_NAME]


def _identifiers(names: Any) -> dict[str, str]:
    """Distinct MATLAB identifiers for ``names`` (:func:`_identifier`, :func:`_distinct`:
    ``acc+motor`` and ``acc_motor`` were both written as ``acc_motor``, one of them lost)."""
    return _distinct(names, made=_identifier, limit=_MATLAB_NAME)


def _distinct(names: Any, *, made: Callable[[str], str], key: Callable[[str], str] = str,
              limit: int | None = None) -> dict[str, str]:
    """``{name: new name}``, the new names distinct as ``key`` compares them: a name that
    ``made`` leaves as it is keeps it (the first of those ``key`` takes alike), the others are
    ``made(name)`` and, if that is taken, get ``_2``, ``_3``, ... (at most ``limit``
    characters with it)."""
    names = list(names)
    out: dict[str, str] = {}
    taken: set[str] = set()
    for name in names:
        if made(name) == name and key(name) not in taken:
            out[name] = name
            taken.add(key(name))
    for name in names:
        if name in out:
            continue
        base, i = made(name), 2
        new = base
        while key(new) in taken:
            suffix = f"_{i}"
            new, i = base[:None if limit is None else limit - len(suffix)] + suffix, i + 1
        taken.add(key(new))
        out[name] = new
    return {name: out[name] for name in names}  # in the order given


def _cell(values: Any) -> np.ndarray:
    """A MATLAB cell array (1 x n) of strings."""
    cell = np.empty((1, len(values)), dtype=object)
    for i, v in enumerate(values):
        cell[0, i] = str(v)
    return cell


def export_mat(session: Session, path: Path, *, inputs: list[str], outputs: list[str],
               window: Any, dt: float | None,
               iddata: Literal["required", "if-found"] = "required") -> str:
    """One ``.mat`` file: iddata's ``u``, ``y``, ``Ts``, names and units, and every stream.

    ``iddata``: ``"required"``, the iddata part must be built (a one-line error otherwise);
    ``"if-found"``, it is left out, with a warning, when the channels or window are not in the
    session (the defaults on a log imported from elsewhere: every stream is still written).
    Returns what was left out (``""`` if nothing)."""
    from scipy.io import savemat

    from sysid.errors import ParameterError, SysIdError
    from sysid.session_io import host_windows, load_experiments

    data, left_out = None, ""
    try:
        data = load_experiments(session.path, inputs=inputs, outputs=outputs, window=window,
                                dt=dt, detrend=None, verb="export as iddata")
    except (SysIdError, SessionError) as exc:  # SessionError: no such phase
        if iddata == "required":  # a value given (--dt, a window): its own advice
            advice = "" if isinstance(exc, ParameterError) else \
                "; choose --inputs/--outputs/--window"
            raise GroundStationError(f"the iddata part (u, y) cannot be built: {exc}{advice}"
                                     ) from None
        left_out = f"no iddata part (u, y): {exc}"
        log.warning("%s; every stream is written, pass --inputs/--outputs/--window for u, y",
                    left_out)
    streams: dict[str, dict[str, Any]] = {}
    units: dict[str, dict[str, str]] = {}
    names: dict[str, dict[str, Any]] = {}  # MATLAB's names back to the session's
    stream_ids = _identifiers(session.streams)
    for name, stream in session.streams.items():
        cols = _columns(session, name)
        labels = _labels(session, cols)
        ids = _identifiers(labels.values())
        field_ids = {f: ids[labels[f]] for f in cols}
        streams[stream_ids[name]] = {
            field_ids[f]: (_cell(c).T if isinstance(c, list) else
                           np.asarray(c, dtype=float).reshape(-1, 1))
            for f, c in cols.items()}
        units[stream_ids[name]] = {field_ids[f]: stream.units.get(f, "") for f in cols}
        names[stream_ids[name]] = {"stream": name,
                                   "fields": {field_ids[f]: f for f in cols}}
    metadata = _metadata(session)
    meta_ids = _identifiers(metadata)
    meta = {meta_ids[k]: json.dumps(v) if not isinstance(v, str) else v
            for k, v in metadata.items()}
    content: dict[str, Any] = {} if data is None else _iddata_part(
        data, window=window, names=[label for label, _ in host_windows(session, window)])
    with whole_file(path) as part:
        savemat(part, {**content, "streams": streams, "units": units, "names": names,
                       "metadata": meta},
                long_field_names=True, do_compression=True, oned_as="column", appendmat=False)
    return left_out


def _iddata_part(data: list[Any], *, window: Any, names: list[str]) -> dict[str, Any]:
    """iddata's fields for the experiments ``data`` (IOData, one grid): ``u``, ``y`` as
    matrices for one experiment, as 1 x E cell arrays of matrices for several (iddata's
    multi-experiment form), and ``ExperimentName`` (``names``, their windows) either way."""
    first = data[0]

    def part(values: list[np.ndarray]) -> np.ndarray:
        if len(values) == 1:
            return np.asarray(values[0], dtype=float)
        cell = np.empty((1, len(values)), dtype=object)
        for i, v in enumerate(values):
            cell[0, i] = np.asarray(v, dtype=float)
        return cell

    return {"u": part([d.u for d in data]), "y": part([d.y for d in data]),
            "Ts": float(first.dt), "InputName": _cell(first.input_names),
            "OutputName": _cell(first.output_names), "InputUnit": _cell(first.input_units),
            "OutputUnit": _cell(first.output_units), "ExperimentName": _cell(names),
            "Window": "all" if window is None else str(window)}


def export_parquet(session: Session, folder: Path) -> list[Path]:
    """One ``STREAM.parquet`` per stream in ``folder`` (units in the field metadata; named as
    :func:`export_csv` names them) and ``metadata.json``; returns the files."""
    try:
        pa = importlib.import_module("pyarrow")
        pq = importlib.import_module("pyarrow.parquet")
    except ImportError:
        raise GroundStationError("--to parquet needs pyarrow: pip install pyarrow "
                                 "(or use --to csv)") from None
    folder.mkdir(parents=True, exist_ok=True)
    files = []
    names = _file_names(session.streams, ".parquet")
    for name, stream in session.streams.items():
        cols = _columns(session, name)
        labels = _labels(session, cols)
        fields = [pa.field(labels[f], pa.string() if isinstance(c, list) else
                           pa.from_numpy_dtype(c.dtype), metadata={"unit": stream.units.get(f, "")})
                  for f, c in cols.items()]
        table = pa.Table.from_arrays([pa.array(c) for c in cols.values()],
                                     schema=pa.schema(fields, metadata={
                                         "stream": name, "kind": stream.kind}))
        path = folder / names[name]
        with whole_file(path) as part:
            pq.write_table(table, part)
        files.append(path)
    return [*files, write_metadata(session, folder, files=names)]


def _target(session: Path, to: Format, out: Path | None, force: bool) -> Path:
    """The output (a .mat file or a folder), checked before any work."""
    from cfcommon.cli import check_folder, check_output, names_a_file

    if to == "mat":
        path = out or session.with_suffix(".mat")
        return check_output(path, option="--out", suffixes=(".mat",), inputs=[session],
                            overwrite=force, force_flag="--force")
    if out is not None and str(out) == "-":  # the usual name for standard output
        raise click.BadParameter(f"'-' (standard output): {to} export writes one file per "
                                 "stream into a folder; give a folder (its full path for "
                                 "one named '-')", param_hint="--out")
    folder = out or session.with_name(f"{session.stem}-{to}")
    if folder.exists() and not folder.is_dir():
        raise click.BadParameter(f"{str(folder)!r} is a file; give a folder", param_hint="--out")
    if names_a_file(folder):
        raise click.BadParameter(f"{str(folder)!r} names a file, but --to {to} writes one file "
                                 f"per stream into a folder; give a folder (e.g. "
                                 f"{str(folder.with_suffix(''))!r}), or --to mat for one file",
                                 param_hint="--out")
    if folder.is_dir() and any(folder.iterdir()) and not force:
        raise click.BadParameter(f"{str(folder)!r} is not empty; pass --force to write "
                                 "over the files of the same names, or choose another "
                                 "folder", param_hint="--out")
    if folder.is_dir():  # the files go into it
        if not os.access(folder, os.W_OK | os.X_OK):
            raise _not_writable(folder)
        return folder
    check_folder(folder.parent, option="--out")  # made with its missing parents, as import's
    return folder


def _not_writable(folder: Path) -> click.BadParameter:
    return click.BadParameter(f"folder {str(folder)!r} is not writable", param_hint="--out")


class _Choice(click.Choice):
    """click's choice, whose "missing" message lists the choices on one line (click's own puts
    each on a tab-indented line of its own)."""

    def get_missing_message(self, param: click.Parameter, ctx: click.Context | None) -> str:
        *rest, last = map(str, self.choices)
        return f"Choose {', '.join(rest)} or {last}" if rest else f"Choose {last}"


@click.command("export", short_help="Write a session as CSV files, a MATLAB .mat or Parquet.")
@click.argument("session", type=click.Path(path_type=Path))
@click.option("--to", "to", type=_Choice(["csv", "mat", "parquet"]), required=True,
              help="csv: one file per stream; mat: one file for MATLAB's iddata and every "
                   "stream; parquet: one file per stream (needs pyarrow).")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Output folder (csv, parquet) or .mat file, its missing folders made "
                   "[default: next to SESSION, SESSION-csv/, SESSION-parquet/ or SESSION.mat].")
@click.option("--force", is_flag=True, help="Replace an existing output.")
@click.option("--inputs", default=DEFAULT_INPUTS, show_default=True,
              help="mat: iddata inputs u (streams, stream.field or group.variable), as sysid.")
@click.option("--outputs", default=DEFAULT_OUTPUTS, show_default=True,
              help="mat: iddata outputs y, as sysid.")
@click.option("--window", default="auto", show_default=True,
              help="mat: as sysid: auto (each excitation phase, else each airborne segment), "
                   "a phase name or kind, T0:T1 (session seconds), PHASE@T0:T1, or all; "
                   "several experiments are iddata's multi-experiment form.")
@click.option("--dt", type=FiniteFloat(min=0, min_open=True), default=None,
              help="mat: sample time Ts of u and y, s [default: the logged period, as sysid].")
def command(session: Path, to: Format, out: Path | None, force: bool, inputs: str,
            outputs: str, window: str, dt: float | None) -> None:
    """Write SESSION for pandas, MATLAB or Arrow users.

    \b
    Examples:
      groundstation export flight.h5 --to csv              # flight-csv/STREAM.csv
      groundstation export flight.h5 --to mat --window all # flight.mat: iddata u, y, Ts, ...
      groundstation export flight.h5 --to parquet --out parquet/
    """
    from sysid.cli_support import parse_window
    from sysid.errors import ParameterError

    ctx = click.get_current_context()
    given = [f"--{n}" for n in ("inputs", "outputs", "window", "dt")
             if ctx.get_parameter_source(n) is not click.core.ParameterSource.DEFAULT]
    if to != "mat" and given:  # they shape the iddata part only: csv/parquet ignored them
        raise click.BadParameter(f"for --to mat only (its iddata u, y); --to {to} writes "
                                 "every stream whole",
                                 param_hint=", ".join(f"'{g}'" for g in given))
    target = _target(session, to, out, force)
    s = open_session(session)
    if to != "mat":  # mat: u and y are read through sysid.session_io, which warns
        warn_problems(s, log)
    if to == "mat":
        try:
            win = parse_window(window)
        except ParameterError as exc:
            raise click.BadParameter(str(exc), param_hint="--window") from None
        names = [[n.strip() for n in v.split(",") if n.strip()] for v in (inputs, outputs)]
        left_out = export_mat(s, target, inputs=names[0], outputs=names[1], window=win,
                              dt=dt, iddata="required" if given else "if-found")
        click.echo(f"wrote {target}" + (" (every stream; no iddata part (u, y): pass "
                                        "--inputs/--outputs/--window)" if left_out else ""))
        return
    try:
        files = export_csv(s, target) if to == "csv" else export_parquet(s, target)
    except PermissionError as exc:  # a file in the folder, or the folder, refused to us
        where = Path(exc.filename) if exc.filename else target
        raise _not_writable(where if where == target or where.is_dir() else where.parent) \
            from None
    click.echo(f"wrote {len(files)} files to {target}")
