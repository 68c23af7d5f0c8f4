"""Shared parts of the ``sysid`` command line: option parsing, loading sessions, result tables.

Sessions are read through :mod:`sysid.session_io` (channels, window, ZOH grid). User mistakes
(:class:`~sysid.errors.SysIdError`, session-file errors, missing files) print one line and exit
with code 2, never a traceback. ``--json`` prints a machine-readable result on stdout; tables
and progress are for people (progress goes to stderr).
"""

from __future__ import annotations

import importlib
import logging
import shlex
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console
from rich.table import Table

from cfcommon.cli import (
    DEFAULT_INPUTS,
    DEFAULT_OUTPUTS,
    FiniteFloat,
    OneLineErrorGroup,
    check_output,
    output_console,
    output_table,
)
from sysid.comparison import CompareResult
from sysid.data import IOData
from sysid.errors import (
    DataError,
    MissingDependencyError,
    ModelFileError,
    ParameterError,
    SysIdError,
)
from sysid.model import StateSpaceModel, load_model
from sysid.model_io import holds_a_session
from sysid.pole_format import POLE_COLUMNS, pole_cells, pole_rows
from sysid.session_io import (
    AUTO,
    MAX_SHOWN_NAME,
    SessionFileError,
    Window,
    load_sessions,
    parse_window,
    session_window,
    shown_name,
)
from sysid.stability import NEAR_BAND
from sysid.validate import default_window, min_fit_samples

__all__ = [
    "DETREND_OPTION",
    "GRID_FORMS",
    "JSON_OPTION",
    "MAX_WINDOW_S",
    "MODEL_SUFFIXES",
    "RRD_FORCE_OPTION",
    "RRD_OPTION",
    "SESSION_DEFAULTS",
    "Group",
    "check_rrd",
    "check_window_samples",
    "console",
    "experiment_label",
    "fit_table",
    "fits_json",
    "grid_max",
    "grid_min",
    "load_flights",
    "load_groups",
    "load_model_arg",
    "parse_grid",
    "parse_window",
    "parse_windows",
    "pole_kind",
    "pole_table",
    "poles_rich_table",
    "require_viz",
    "session_args",
    "session_options",
    "split_names",
    "window_texts",
    "write_rrd",
]

log = logging.getLogger(__name__)

#: Suffixes a model file may have (see :mod:`sysid.model_io`).
MODEL_SUFFIXES = (".h5", ".hdf5", ".json", ".mat")


class Group(OneLineErrorGroup):
    """The ``sysid`` group: :class:`cfcommon.cli.OneLineErrorGroup` with sysid's errors."""

    user_errors = (SysIdError, SessionFileError)

    def user_error_message(self, exc: Exception, *, ctx: click.Context) -> str | None:
        if isinstance(exc, np.linalg.LinAlgError):
            return f"numerical failure ({exc}); try another order or horizons"
        return super().user_error_message(exc, ctx=ctx)


# ------------------------------------------------------------------------------- parsing
#: The forms of a sweep's grid option (:func:`parse_grid`), for help and messages.
GRID_FORMS = "START:STOP (every value), START:STOP:STEP or a,b,c"


def parse_grid(*, text: str, option: str, minimum: int = 1,
               maximum: int | None = None) -> range | list[int]:
    """``20:80:10`` -> range(20, 81, 10) (stop included); ``6,8`` -> [6, 8]; ``8`` -> [8].

    Every value must be an integer ``>= minimum`` (and ``<= maximum`` when given). A
    ``START:STOP:STEP`` stays a lazy :class:`range`, so a huge range can be refused (by its
    length or largest value) before it takes memory."""
    try:
        if ":" in text:
            parts = [int(x) for x in text.split(":")]
            if len(parts) > 3:
                raise ValueError
            start, stop, step = [*parts, 1][:3] if len(parts) == 2 else parts
            if step < 1 or stop < start:
                raise ValueError
            values: range | list[int] = range(start, stop + 1, step)
        else:
            values = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ParameterError(f"{option} {text!r}: use {GRID_FORMS} (STOP >= START, STEP >= 1) "
                             "or one integer") from None
    if not values or grid_min(values) < minimum:
        what = "positive integers" if minimum == 1 else f"integers >= {minimum}"
        raise ParameterError(f"{option} {text!r}: give {what}")
    if maximum is not None and grid_max(values) > maximum:
        raise ParameterError(f"{option} {text!r}: at most {maximum}")
    return values


def grid_min(values: range | Sequence[int]) -> int:
    return values[0] if isinstance(values, range) else min(values)


def grid_max(values: range | Sequence[int]) -> int:
    return values[-1] if isinstance(values, range) else max(values)


def split_names(text: str) -> list[str]:
    return [x.strip() for x in text.split(",") if x.strip()]


#: Longest --window-s, seconds (a day: far beyond any flight; 1e308 overflowed the sample count).
MAX_WINDOW_S = 86_400.0
WINDOW_HELP = ("Window: auto (the excitation phases, else the airborne-N phases, each its "
               "own experiment), a phase name or kind, T0:T1 (session seconds), PHASE@T0:T1 "
               "(seconds from the phase start; PHASE@T0: to its end) or all. "
               "SESSION=WINDOW applies to that session only (file name or path); repeatable.")


#: The default of each option of :func:`session_options`, by parameter name.
SESSION_DEFAULTS: dict[str, Any] = {"inputs": DEFAULT_INPUTS, "outputs": DEFAULT_OUTPUTS,
                                    "windows": ("auto",), "dt": None, "detrend": "mean"}


DETREND_OPTION = click.option(
    "--detrend", default=SESSION_DEFAULTS["detrend"], show_default=True,
    type=click.Choice(["mean", "linear", "none"]),
    help="Removed from each channel of each experiment first: its mean, a straight line (slow "
         "drift), or nothing.")


def session_options(func: Callable) -> Callable:
    """Options shared by every command that reads sessions."""
    opts = [
        click.option("--inputs", default=SESSION_DEFAULTS["inputs"], show_default=True, help=(
                     "Input channels: STREAM, STREAM.FIELD, group.variable or a variable "
                     "group (gyro: gyro.x, gyro.y, gyro.z), comma-separated.")),
        click.option("--outputs", default=SESSION_DEFAULTS["outputs"], show_default=True,
                     help="Output channels, as --inputs (default: what the motors drive "
                          "directly; see docs/sysid.md)."),
        click.option("--window", "windows", multiple=True, default=SESSION_DEFAULTS["windows"],
                     show_default=True, help=WINDOW_HELP),
        click.option("--dt", default=SESSION_DEFAULTS["dt"], type=FiniteFloat(min=1e-4),
                     help="Grid period in seconds (default: the logged period; faster streams "
                          "are low-passed before the hold)."),
        DETREND_OPTION,
    ]
    for opt in reversed(opts):
        func = opt(func)
    return func


def session_args(opts: dict[str, Any]) -> list[str]:
    """The options of :func:`session_options` in ``opts`` that differ from their defaults, as
    command-line arguments (``["--outputs", "gyro.x", "--window", "prbs"]``): what a command
    that suggests another one passes on, so that it reads the same data."""
    args: list[str] = []
    for name, default in SESSION_DEFAULTS.items():
        value = opts.get(name, default)
        if value is None or value == default or (name == "windows" and tuple(value) == default):
            continue
        option = "--window" if name == "windows" else f"--{name}"
        for one in value if name == "windows" else (value,):
            args += [option, f"{one:g}" if isinstance(one, float) else str(one)]
    return args


def window_texts(texts: Sequence[str]) -> dict[str | None, str]:
    """``--window`` values by whose window each sets (a session as named, None for every
    session's), each as given; two for one are refused in one line."""
    given: dict[str | None, str] = {}  # two for one: the user meant one
    for text in texts:
        session, eq, _ = text.partition("=")
        whose = session.strip() if eq else None
        if whose in given:
            who = "every session" if whose is None else f"session {whose!r}"
            raise ParameterError(f"--window {given[whose]!r} and --window {text!r}: two windows "
                                 f"for {who}; give one (a flight's phases are each their own "
                                 "experiment with the default auto)")
        given[whose] = text
    return given


def parse_windows(texts: Sequence[str]) -> tuple[Window, dict[str, Window]]:
    """``--window`` values: ``(window for every session, {session: its own window})``."""
    common: Window = AUTO
    own: dict[str, Window] = {}
    for whose, text in window_texts(texts).items():
        try:
            if whose is None:
                common = parse_window(text)
            else:
                own[whose] = parse_window(text.partition("=")[2])
        except ParameterError as exc:
            raise ParameterError(f"--{exc}") from None
    return common, own


def load_groups(paths: Sequence[Path], *, opts: dict[str, Any],
                inputs: Sequence[str] | None = None, outputs: Sequence[str] | None = None,
                verb: str = "identify from", elsewhere: Sequence[Path] = (),
                min_states: int | None = None) -> list[list[IOData]]:
    """The experiments of each session, as the session options select them; ``verb`` is
    what they are for (:func:`sysid.session_io.load_experiments`). ``elsewhere``: the
    command's other sessions, read by another call (``--validate``), whose ``--window
    SESSION=...`` the options may hold too. ``min_states``: the smallest order the models
    scored on these data may have; each experiment of a window the user gave (not ``auto``)
    must hold the samples such a model's fit needs (:func:`check_window_samples`)."""
    common, own = parse_windows(opts["windows"])
    try:
        groups = load_sessions(
            list(paths), inputs=inputs or split_names(opts["inputs"]),
            outputs=outputs or split_names(opts["outputs"]), window=common, windows=own,
            elsewhere=list(elsewhere), dt=opts["dt"],
            detrend=None if opts["detrend"] == "none" else opts["detrend"], verb=verb)
    except DataError as exc:  # a channel the session lacks: say which option chooses them
        channel = getattr(exc, "channel", None)
        if channel is None or channel.problem != "unknown":
            raise
        role = f"{channel.role}s"
        if (role == "inputs" and inputs) or (role == "outputs" and outputs):
            # the model's channels (compare, resid): no option chooses them
            logged = ", ".join(map(_stream_name, channel.logged)) or "none"
            raise DataError(f"{exc.path}: the model's {channel.role} {shown_name(channel.name)} "
                            f"is not logged in this session (its log streams: {logged}); "
                            f"{verb.split()[0]} the model on sessions that log the channels it "
                            "was identified with") from None
        raise DataError(f"{exc}; choose the {role} with --{role}") from None
    if min_states is not None:
        check_window_samples(paths, groups, windows=opts["windows"], min_states=min_states)
    return groups


def check_window_samples(paths: Sequence[Path], groups: Sequence[Sequence[IOData]], *,
                         windows: Sequence[str], min_states: int) -> None:
    """Refuse, in one line naming the session and its ``--window``, an experiment of a window
    the user gave that holds fewer samples than a model of ``min_states`` states (the
    smallest candidate) needs for a fit with its own initial state
    (:func:`sysid.validate.min_fit_samples`): a 15-sample window on the validating session
    ran the whole search, its score's tolerance falling back to a guess, and capped every
    simulation window of the fits at 15 samples. ``auto`` windows are left alone: a short
    phase among long ones is left out of the score with a warning (:mod:`sysid.holdout`)."""
    given = window_texts(windows)
    own = {whose: text for whose, text in given.items() if whose is not None}
    for path, group in zip(paths, groups, strict=True):
        text = session_window(path, own, given.get(None, AUTO))  # as given: V.h5=prbs@0:1
        if parse_window(text.partition("=")[2] if "=" in text else text) == AUTO:
            continue
        for e in group:
            need = min_fit_samples(n_states=min_states, n_outputs=e.n_outputs)
            if e.n_samples >= need:
                continue
            label = experiment_label(e.source) if "#" in e.source else path.name
            raise DataError(
                f"{label}: --window {text} holds {e.n_samples} samples ({e.n_samples * e.dt:.3g} "
                f"s at dt {e.dt:g} s), fewer than the {need} the smallest candidate model "
                f"(order {min_states}, {e.n_outputs} output(s)) needs to be scored with its own "
                f"initial state; give {path.name} a window of {need * e.dt:.3g} s at least "
                f"(--window {path.name}=...) or leave the session out")


def _stream_name(name: str) -> str:
    """A stream's name for a list in a message: as it is, or cut when long (:func:`shown_name`)."""
    return name if len(name) <= MAX_SHOWN_NAME else shown_name(name)


def load_flights(paths: Sequence[Path], *, opts: dict[str, Any],
                 inputs: Sequence[str] | None = None, outputs: Sequence[str] | None = None,
                 verb: str = "identify from", elsewhere: Sequence[Path] = (),
                 min_states: int | None = None) -> list[IOData]:
    """Every experiment of the sessions, in order (:func:`load_groups` flattened)."""
    return [e for g in load_groups(paths, opts=opts, inputs=inputs, outputs=outputs,
                                   verb=verb, elsewhere=elsewhere, min_states=min_states)
            for e in g]


def load_model_arg(model_path: Path, sessions: Sequence[Path], *, command: str
                   ) -> StateSpaceModel:
    """The MODEL argument of ``sysid COMMAND MODEL SESSIONS...``. When it is a session and one
    of ``sessions`` a model file, the arguments were swapped: one line says so and gives the
    command in the right order (other errors as :func:`sysid.model.load_model`'s)."""
    try:
        return load_model(model_path)
    except ModelFileError:
        if not holds_a_session(model_path):
            raise
        for other in sessions:
            try:
                load_model(other)
            except ModelFileError:
                continue
            order = [other, model_path, *(p for p in sessions if p != other)]
            raise ModelFileError(
                f"{model_path} is a flight session and {other} a model: the model comes "
                f"first, swap them: sysid {command} {shlex.join(map(str, order))}") from None
        raise


# ------------------------------------------------------------------------------- output
def pole_table(model: StateSpaceModel) -> list[dict[str, float]]:
    """The model's poles as :func:`sysid.pole_format.pole_rows` describes them (MATLAB's
    ``damp``: modulus, angle, natural frequency, damping ratio, time constant)."""
    return pole_rows(model.poles(), dt=model.dt)


def poles_rich_table(model: StateSpaceModel, *, title: str,
                     console: Console | None = None) -> Table:
    """The one pole table every command prints (:mod:`sysid.pole_format`); plain when
    ``console`` is not a terminal."""
    table = output_table(*POLE_COLUMNS, title=title, console=console or Console())
    for cells in pole_cells(pole_table(model)):
        table.add_row(*cells)
    return table


def experiment_label(source: str) -> str:
    """``f0.h5`` or ``f0.h5#airborne-2`` for an experiment's ``source``."""
    path, hash_, label = source.partition("#")
    return Path(path).name + hash_ + label


def console() -> Console:
    """Output console: on a terminal at least 100 columns; piped, plain and never wrapped."""
    out = output_console()
    return Console(highlight=False, width=max(out.width, 100)) if out.is_terminal else out


#: A fit below this (the model's error 100 times the signal's spread) is reported as diverged.
DIVERGED_FIT = -1e4


def fit_or_none(fit: float) -> float | None:
    """The fit in percent, or None when the model output diverged (non-finite or below
    :data:`DIVERGED_FIT`): "diverged" in tables, ``null`` in JSON."""
    return float(fit) if np.isfinite(fit) and fit >= DIVERGED_FIT else None


def fit_table(*, title: str, names: Sequence[str], rows: list[tuple[str, np.ndarray]],
              console: Console | None = None) -> Table:
    table = output_table("", *names, title=title, console=console or Console())
    first = table.columns[0]  # row labels never wrap
    first.no_wrap = True
    first.min_width = max((len(label) for label, _ in rows), default=1)
    for label, fit in rows:
        table.add_row(label, *[fit_cell(f) for f in fit])
    return table


def fit_cell(fit: float) -> str:
    """A fit for a table: ``"87.3"``, ``"diverged"``, or ``"n/a"`` where the measured channel
    does not move (the fit's denominator is zero: NaN)."""
    if np.isnan(fit):
        return "n/a"
    return "diverged" if fit_or_none(fit) is None else f"{fit:.1f}"


def fits_json(res: CompareResult, fits: np.ndarray | None = None) -> dict[str, float | None]:
    """``{channel: fit or None}`` of ``fits`` (default: the overall fit of ``res``)."""
    values = res.fit if fits is None else fits
    return {n: fit_or_none(f) for n, f in zip(res.output_names, values, strict=True)}


def require_viz() -> Any:
    """:mod:`sysid.viz`, or a one-line error naming --rrd when it cannot be imported."""
    try:
        return importlib.import_module("sysid.viz")
    except ImportError as exc:
        raise MissingDependencyError(f"--rrd needs sysid.viz, which cannot be imported ({exc});"
                                     " drop --rrd") from None


def check_rrd(rrd: Path | None, *, inputs: Sequence[Path], force: bool) -> Path | None:
    """Refuse a ``--rrd`` path before any work: it must end in .rrd, be no input of the
    command, its folder must be writable (a missing one is made when the file is written),
    and an existing file is replaced only with ``force`` (``--force``), as every output is."""
    if rrd is None:
        return None
    check_output(rrd, option="--rrd", suffixes=(".rrd",), inputs=inputs, overwrite=force,
                 force_flag="--force")
    require_viz()
    return rrd


def write_rrd(*, path: Path, name: str, model: StateSpaceModel,
               comparisons: Sequence[CompareResult] = (), sweep: Any = None,
               residuals: Any = None, validation: Sequence[CompareResult] = ()) -> None:
    """Write ``model`` (its singular values, poles), comparisons and a sweep to ``path`` with
    :func:`sysid.viz.log_identification`; comparisons on validation records go in
    ``validation`` (entities of their own, ``/sysid/validation/<mode>``). One-line error when
    :mod:`sysid.viz` is missing or the file cannot be written."""
    viz = require_viz()
    try:
        rec, _ = viz.open_recording(name=name, mode="save", rrd_path=path)
        try:
            viz.log_identification(rec=rec, model=model, comparisons=list(comparisons),
                                   sweep=sweep, residuals=residuals,
                                   validation=list(validation))
        except BaseException:
            viz.discard_file(rec)  # no file rather than part of one
            raise
        viz.close_file(rec, path)
    except (OSError, RuntimeError) as exc:
        lines = str(exc).strip().splitlines()
        reason = getattr(exc, "strerror", None) or (lines[0] if lines else type(exc).__name__)
        raise ParameterError(f"--rrd {str(path)!r} could not be written: {reason}") from None
    log.info("wrote %s", path)


RRD_OPTION = click.option("--rrd", type=click.Path(dir_okay=False, path_type=Path),
                          help="Also write the results to this Rerun recording (.rrd); an "
                               "existing file needs --force.")
#: ``--force`` of a command whose only output is ``--rrd`` (``compare``, ``resid``).
RRD_FORCE_OPTION = click.option("--force", is_flag=True,
                                help="Replace --rrd if it exists (never an input file).")
JSON_OPTION = click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")


# ------------------------------------------------------------------------------- commands


def default_compare_mode(model: StateSpaceModel, *, n_samples: int | None = None
                         ) -> tuple[str, dict[str, Any]]:
    """``(label, compare keywords)`` when the user chose no mode: whole-record simulation, or
    windowed simulation (:func:`sysid.validate.simulation_window`, 2 s) for a model with a pole
    at ``|z| >= INTEGRATING_RADIUS`` (simulating a whole flight through an integrator measures
    only its drift). ``n_samples``: the shortest record, which caps the window (as
    ``identify`` caps it); the label then says so."""
    window = default_window(model, n_samples=n_samples)  # the one rule (identify's too)
    if window is not None:
        full = default_window(model)
        capped = (f" (the shortest record: shorter than {full:.3g} s)"
                  if round(window / model.dt) < round(full / model.dt) else "")
        return (f"simulation, {window:.3g} s windows{capped}", {"window": window})
    return ("simulation", {})


def pole_kind(pole: complex) -> str:
    """What a pole on or near the unit circle is, in a few words: "integrating or nearly"
    within :data:`sysid.stability.NEAR_BAND` of ``z = 1`` (the band ``stability="auto"``
    treats as an integrator's estimate), else "unstable" outside the unit circle, else
    "lightly damped" (a slow oscillation, or a mode near ``z = -1``)."""
    if abs(pole - 1.0) <= NEAR_BAND * (1.0 + 1e-9):  # the band edge, to rounding
        return "integrating or nearly"
    return "unstable" if abs(pole) > 1.0 else "lightly damped"
