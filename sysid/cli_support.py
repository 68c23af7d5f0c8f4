"""Shared parts of the ``sysid`` command line: option parsing, loading sessions, result tables.

Sessions are read through :mod:`sysid.session_io` (channels, window, ZOH grid). User mistakes
(:class:`~sysid.errors.SysIdError`, session-file errors, missing files) print one line and exit
with code 2, never a traceback. ``--json`` prints a machine-readable result on stdout; tables
and progress are for people (progress goes to stderr).
"""

from __future__ import annotations

import importlib
import logging
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console
from rich.table import Table

from sysid.comparison import CompareResult
from sysid.data import IOData
from sysid.errors import MissingDependencyError, ParameterError, SysIdError
from sysid.model import StateSpaceModel
from sysid.session_io import SessionFileError, Window, load_sessions

__all__ = [
    "JSON_OPTION",
    "RRD_OPTION",
    "Group",
    "console",
    "fit_table",
    "fits_json",
    "load_flights",
    "parse_range",
    "parse_window",
    "pole_table",
    "session_options",
    "split_names",
    "write_rrd",
]

log = logging.getLogger(__name__)


class Group(click.Group):
    """A click group whose user errors print one line and exit 2, never a traceback."""

    def invoke(self, ctx: click.Context) -> Any:
        try:
            return super().invoke(ctx)
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
        except ValueError:
            raise ParameterError(f"--window {text!r}: use a phase name, T0:T1 seconds or all")\
                from None
        return (t0, t1)
    return text


def parse_range(*, text: str, option: str) -> list[int]:
    """``20:80:10`` -> 20, 30, ..., 80 (stop included); ``6,8`` -> 6, 8; ``8`` -> 8."""
    try:
        if ":" in text:
            parts = [int(x) for x in text.split(":")]
            start, stop, step = [*parts, 1][:3] if len(parts) == 2 else parts
            if step < 1 or stop < start or len(parts) > 3:
                raise ValueError
            return list(range(start, stop + 1, step))
        values = [int(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ParameterError(f"{option} {text!r}: use START:STOP:STEP, a,b,c or one integer")\
            from None
    if not values or min(values) < 1:
        raise ParameterError(f"{option} {text!r}: give positive integers")
    return values


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
        click.option("--dt", default=0.02, show_default=True, type=click.FloatRange(min=1e-4),
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


def write_rrd(*, path: Path, name: str, model: StateSpaceModel,
               comparisons: Sequence[CompareResult] = (), sweep: Any = None) -> None:
    """Write ``model`` (its singular values, poles), comparisons and a sweep to ``path`` with
    :func:`sysid.viz.log_identification`; one-line error when :mod:`sysid.viz` is missing."""
    try:
        viz = importlib.import_module("sysid.viz")
    except ImportError as exc:
        raise MissingDependencyError(f"--rrd needs sysid.viz, which cannot be imported ({exc});"
                                     " drop --rrd") from None
    rec, _ = viz.open_recording(name=name, mode="save", rrd_path=path)
    try:
        viz.log_identification(rec=rec, model=model, comparisons=list(comparisons),
                               sweep=sweep)
    finally:
        rec.disconnect()
    log.info("wrote %s", path)


RRD_OPTION = click.option("--rrd", type=click.Path(dir_okay=False, path_type=Path),
                    help="Also write the results to this Rerun recording (.rrd).")
JSON_OPTION = click.option("--json", "as_json", is_flag=True, help="Print the result as JSON.")


# ------------------------------------------------------------------------------- commands
