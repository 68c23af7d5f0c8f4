"""Shared parts of the ``sysid`` command line: option parsing, loading sessions, result tables.

Sessions are read through :mod:`sysid.session_io` (channels, window, ZOH grid). User mistakes
(:class:`~sysid.errors.SysIdError`, session-file errors, missing files) print one line and exit
with code 2, never a traceback. ``--json`` prints a machine-readable result on stdout; tables
and progress are for people (progress goes to stderr).
"""

from __future__ import annotations

import importlib
import logging
import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console
from rich.table import Table

from sysid.cli_types import FiniteFloat, check_output
from sysid.comparison import CompareResult
from sysid.data import IOData
from sysid.errors import MissingDependencyError, ParameterError, SysIdError
from sysid.model import StateSpaceModel
from sysid.session_io import SessionFileError, Window, load_sessions

__all__ = [
    "JSON_OPTION",
    "MODEL_SUFFIXES",
    "RRD_OPTION",
    "Group",
    "check_rrd",
    "console",
    "fit_table",
    "fits_json",
    "grid_max",
    "grid_min",
    "load_flights",
    "parse_grid",
    "parse_window",
    "pole_table",
    "require_viz",
    "session_options",
    "split_names",
    "write_rrd",
]

log = logging.getLogger(__name__)

#: Suffixes a model file may have (see :mod:`sysid.model_io`).
MODEL_SUFFIXES = (".h5", ".hdf5", ".json", ".mat")


class Group(click.Group):
    """A click group whose user errors print one line and exit 2, never a traceback."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
        except click.UsageError as exc:  # bad option values, refused output files
            if isinstance(exc, click.exceptions.NoArgsIsHelpError):  # `sysid X` alone: help
                raise
            where = exc.ctx.command_path if exc.ctx is not None else ctx.command_path
            msg = f"{exc.format_message()} (see '{where} -h')"
        except (SysIdError, SessionFileError) as exc:
            msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        except (FileNotFoundError, PermissionError, IsADirectoryError) as exc:
            msg = f"{exc.strerror}: {exc.filename}"
        except np.linalg.LinAlgError as exc:
            msg = f"numerical failure ({exc}); try another order or horizons"
        click.echo(f"error: {msg}", err=True)
        sys.exit(2)


# ------------------------------------------------------------------------------- parsing
def parse_window(text: str) -> Window:
    """``all`` -> None, ``T0:T1`` -> host-time seconds, anything else a phase name or kind."""
    if text.lower() in ("all", "none", ""):
        return None
    if ":" in text:
        try:
            t0, t1 = (float(x) for x in text.split(":"))
            if not (math.isfinite(t0) and math.isfinite(t1)):
                raise ValueError
        except ValueError:
            raise ParameterError(f"--window {text!r}: use a phase name, T0:T1 (finite seconds) "
                                 "or all") from None
        return (t0, t1)
    return text


def parse_grid(*, text: str, option: str, minimum: int = 1) -> range | list[int]:
    """``20:80:10`` -> range(20, 81, 10) (stop included); ``6,8`` -> [6, 8]; ``8`` -> [8].

    Every value must be an integer ``>= minimum``. A ``START:STOP:STEP`` stays a lazy
    :class:`range`, so a huge range can be refused (by its length or largest value) before it
    takes memory."""
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
        raise ParameterError(f"{option} {text!r}: use START:STOP:STEP (STOP >= START, STEP >= 1),"
                             " a,b,c or one integer") from None
    if not values or grid_min(values) < minimum:
        what = "positive integers" if minimum == 1 else f"integers >= {minimum}"
        raise ParameterError(f"{option} {text!r}: give {what}")
    return values


def grid_min(values: range | Sequence[int]) -> int:
    return values[0] if isinstance(values, range) else min(values)


def grid_max(values: range | Sequence[int]) -> int:
    return values[-1] if isinstance(values, range) else max(values)


def split_names(text: str) -> list[str]:
    return [x.strip() for x in text.split(",") if x.strip()]


def session_options(func: Callable) -> Callable:
    """Options shared by every command that reads sessions."""
    opts = [
        click.option("--inputs", default="motors", show_default=True, help=(
                     "Input channels: STREAM, STREAM.FIELD or group.variable, comma-separated.")),
        click.option("--outputs", default="acc,gyro", show_default=True,
                     help="Output channels, as --inputs."),
        click.option("--window", default="excitation", show_default=True,
                     help="Phase name or kind, T0:T1 (session seconds), or 'all'."),
        click.option("--dt", default=0.02, show_default=True, type=FiniteFloat(min=1e-4),
                     help="Grid period in seconds (zero-order hold)."),
        click.option("--detrend", default="mean", show_default=True,
                     type=click.Choice(["mean", "linear", "none"])),
    ]
    for opt in reversed(opts):
        func = opt(func)
    return func


def load_flights(paths: Sequence[Path], *, opts: dict[str, Any],
                 inputs: Sequence[str] | None = None,
                 outputs: Sequence[str] | None = None) -> list[IOData]:
    return load_sessions(
        list(paths), inputs=inputs or split_names(opts["inputs"]),
        outputs=outputs or split_names(opts["outputs"]), window=parse_window(opts["window"]),
        dt=opts["dt"], detrend=None if opts["detrend"] == "none" else opts["detrend"])


# ------------------------------------------------------------------------------- output
def pole_table(model: StateSpaceModel) -> list[dict[str, float]]:
    """Poles with modulus, frequency (Hz) and damping ratio of the equivalent s-plane pole.

    :math:`s = \\ln z / \\Delta t`, :math:`f = |\\operatorname{Im} s| / 2\\pi`,
    :math:`\\zeta = -\\operatorname{Re} s / |s|`.
    """
    rows = []
    for z in sorted(model.poles(), key=lambda p: (-abs(p), p.imag)):
        s = np.log(complex(z)) / model.dt if z != 0 else complex(-np.inf)
        rows.append({"re": float(z.real), "im": float(z.imag), "abs": float(abs(z)),
                     "freq_hz": float(abs(s.imag) / (2 * np.pi)) if np.isfinite(s.real) else 0.0,
                     "damping": float(-s.real / abs(s)) if np.isfinite(s.real) and s else 1.0})
    return rows


def console() -> Console:
    return Console(highlight=False, width=max(Console().width, 100))




def fit_table(*, title: str, names: Sequence[str], rows: list[tuple[str, np.ndarray]]) -> Table:
    table = Table("", *names, title=title)
    for label, fit in rows:
        table.add_row(label, *[f"{f:.1f}" if np.isfinite(f) and abs(f) < 1e4 else "diverged"
                               for f in fit])
    return table


def fits_json(res: CompareResult) -> dict[str, float | None]:
    return {n: (float(f) if np.isfinite(f) else None)
            for n, f in zip(res.output_names, res.fit, strict=True)}


def require_viz() -> Any:
    """:mod:`sysid.viz`, or a one-line error naming --rrd when it cannot be imported."""
    try:
        return importlib.import_module("sysid.viz")
    except ImportError as exc:
        raise MissingDependencyError(f"--rrd needs sysid.viz, which cannot be imported ({exc});"
                                     " drop --rrd") from None


def check_rrd(rrd: Path | None, *, inputs: Sequence[Path]) -> Path | None:
    """Refuse a ``--rrd`` path before any work: it must end in .rrd, be no input of the
    command, and its folder must exist and be writable (an existing .rrd is replaced)."""
    if rrd is None:
        return None
    check_output(rrd, option="--rrd", suffixes=(".rrd",), inputs=inputs, overwrite=True)
    require_viz()
    return rrd


def write_rrd(*, path: Path, name: str, model: StateSpaceModel,
               comparisons: Sequence[CompareResult] = (), sweep: Any = None) -> None:
    """Write ``model`` (its singular values, poles), comparisons and a sweep to ``path`` with
    :func:`sysid.viz.log_identification`; one-line error when :mod:`sysid.viz` is missing or
    the file cannot be written."""
    viz = require_viz()
    try:
        rec, _ = viz.open_recording(name=name, mode="save", rrd_path=path)
        try:
            viz.log_identification(rec=rec, model=model, comparisons=list(comparisons),
                                   sweep=sweep)
        finally:
            rec.disconnect()
    except (OSError, RuntimeError) as exc:
        lines = str(exc).strip().splitlines()
        reason = getattr(exc, "strerror", None) or (lines[0] if lines else type(exc).__name__)
        raise ParameterError(f"--rrd {str(path)!r} could not be written: {reason}") from None
    log.info("wrote %s", path)


RRD_OPTION = click.option("--rrd", type=click.Path(dir_okay=False, path_type=Path),
                    help="Also write the results to this Rerun recording (.rrd).")
JSON_OPTION = click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")


# ------------------------------------------------------------------------------- commands
