"""The ``sysid`` command line: identify, compare, order, sweep and export from session files.

Sessions are read through :mod:`sysid.session_io` (channels, window, ZOH grid). User mistakes
(:class:`~sysid.errors.SysIdError`, session-file errors, missing files) print one line and exit
with code 2, never a traceback. ``--json`` prints a machine-readable result on stdout; tables
and progress are for people (progress goes to stderr).
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn
from rich.table import Table

from sysid.cli_support import (
    JSON_OPTION,
    MODEL_SUFFIXES,
    RRD_OPTION,
    Group,
    check_rrd,
    console,
    fit_table,
    fits_json,
    grid_max,
    grid_min,
    load_flights,
    parse_grid,
    parse_window,
    pole_table,
    session_options,
    write_rrd,
)
from sysid.cli_types import FiniteFloat, check_output
from sysid.errors import DataError, HorizonError, SysIdError
from sysid.iem import iem
from sysid.model import StateSpaceModel, load_model
from sysid.moesp import po_moesp
from sysid.order import singular_values
from sysid.sweep import sweep as run_sweep
from sysid.validate import compare

__all__ = ["main", "parse_grid", "parse_window", "pole_table"]

log = logging.getLogger(__name__)

_METHODS: dict[str, Callable[..., StateSpaceModel]] = {"iem": iem, "po-moesp": po_moesp}


_IDENTIFY_WINDOW_S = 2.0
#: Largest sweep grid accepted (models); the thesis' coarse-to-fine search was 756 models.
MAX_SWEEP_MODELS = 100_000
FORCE_OPTION = click.option("--force", is_flag=True,
                            help="Replace --out if it exists (never an input file).")


@click.group(cls=Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="cf-sysid", prog_name="sysid")
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
def main(verbose: int) -> None:
    """Closed-loop subspace identification (IEM, PO-MOESP) of flight sessions.

    \b
    Examples:
      sysid identify flight1.h5 flight2.h5 --order 8 --out model.h5
      sysid compare model.h5 validation.h5 --window-s 5 --horizon 10
    """
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")


@main.command()
@click.argument("sessions", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--method", type=click.Choice(list(_METHODS)), default="iem", show_default=True)
@click.option("--order", default=8, show_default=True, type=click.IntRange(min=1))
@click.option("--past", default=60, show_default=True, type=click.IntRange(min=1))
@click.option("--future", default=17, show_default=True, type=click.IntRange(min=2))
@click.option("--feedthrough/--no-feedthrough", default=None,
              help="Estimate D (default: no for iem, yes for po-moesp).")
@session_options
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="Save the model (.h5, .json or .mat); an existing file needs --force.")
@FORCE_OPTION
@JSON_OPTION
@RRD_OPTION
def identify(sessions: tuple[Path, ...], method: str, order: int, past: int, future: int,
             feedthrough: bool | None, out: Path | None, force: bool, as_json: bool,
             rrd: Path | None, **opts: Any) -> None:
    """Identify one model from one or more sessions (each its own experiment).

    Prints the poles, whether the model and its predictor A - KC are stable, and the fit on
    the identification data (simulation from a least-squares initial state, and one-step
    prediction).

    \b
    Examples:
      sysid identify flight.h5 --order 8 --past 60 --future 17 --out model.h5
      sysid identify imported.h5 --window all --dt 0.01 \\
        --inputs controller.cmd_roll,controller.cmd_pitch,controller.cmd_yaw \\
        --outputs controller.r_roll,controller.r_pitch,controller.r_yaw
    """
    if out is not None:
        check_output(out, option="--out", suffixes=MODEL_SUFFIXES, inputs=sessions,
                     overwrite=force, force_flag="--force")
    check_rrd(rrd, inputs=sessions)
    flights = load_flights(sessions, opts=opts)
    kwargs = {} if feedthrough is None else {"feedthrough": feedthrough}
    with Console(stderr=True).status(f"identifying ({method}, n={order})"):
        model = _METHODS[method](flights, order=order, past=past, future=future, **kwargs)
    # A quadrotor's rates integrate torque: simulating a whole flight drifts even for a good
    # model, so the fit is over short windows (initial state estimated per window).
    window_s = min(_IDENTIFY_WINDOW_S, min(d.n_samples for d in flights) * model.dt)
    sim = compare(model, flights, window=window_s, warn=False)
    pred = compare(model, flights, horizon=1, warn=False)
    if out is not None:
        model.save(out)
    if rrd is not None:
        write_rrd(path=rrd, name=f"identify {sessions[0].name}", model=model,
                   comparisons=[sim, pred])
    poles = pole_table(model)
    if as_json:
        click.echo(json.dumps({
            "sessions": [str(p) for p in sessions], "method": method, "order": order,
            "past": past, "future": future, "n_samples": [d.n_samples for d in flights],
            "dt_s": model.dt, "poles": poles, "stable": model.is_stable,
            "predictor_stable": model.predictor_is_stable,
            "fit_percent": {"simulation": fits_json(sim), "1-step": fits_json(pred)},
            "simulation_window_s": window_s,
            "model": str(out) if out else None}, indent=1))
        return
    con = console()
    table = Table("pole", "re", "im", "|z|", "f [Hz]", "damping", title=f"{method} order {order}")
    for i, p in enumerate(poles):
        table.add_row(str(i), f"{p['re']:.4f}", f"{p['im']:.4f}", f"{p['abs']:.4f}",
                      f"{p['freq_hz']:.2f}", f"{p['damping']:.3f}")
    con.print(table)
    con.print(f"stable: {model.is_stable} (max |pole| {np.abs(model.poles()).max():.4f}); "
              f"predictor A - KC stable: {model.predictor_is_stable}")
    con.print(fit_table(title="fit on the identification data [%]", names=model.output_names,
                         rows=[(f"simulation, {window_s:g} s windows", sim.fit),
                               ("1-step prediction", pred.fit)]))
    if out is not None:
        con.print(f"model saved to {out}")


@main.command("compare")
@click.argument("model_path", metavar="MODEL", type=click.Path(path_type=Path))
@click.argument("sessions", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--horizon", type=click.IntRange(min=1), help="k-step-ahead prediction.")
@click.option("--window-s", type=FiniteFloat(min=0, min_open=True),
              help="Simulate over windows of this many seconds, each from its own x0.")
@click.option("--window", default="excitation", show_default=True,
              help="Phase name or kind, T0:T1 (session seconds), or 'all'.")
@click.option("--detrend", default="mean", show_default=True,
              type=click.Choice(["mean", "linear", "none"]))
@JSON_OPTION
@RRD_OPTION
def compare_cmd(model_path: Path, sessions: tuple[Path, ...], horizon: int | None,
                window_s: float | None, as_json: bool, rrd: Path | None, **opts: Any) -> None:
    """Fit of a model on sessions: per channel and per session, in percent (NRMSE).

    The model's channel names select the session channels and its dt sets the grid. Without
    --horizon/--window-s the whole window is simulated from a least-squares initial state.

    \b
    Example:
      sysid compare model.h5 val1.h5 val2.h5 --window-s 5 --horizon 10
    """
    check_rrd(rrd, inputs=(model_path, *sessions))
    model = load_model(model_path)
    flights = load_flights(sessions, opts={**opts, "dt": model.dt}, inputs=model.input_names,
                    outputs=model.output_names)
    modes: list[tuple[str, dict[str, Any]]] = []
    if window_s is not None:
        modes.append((f"simulation, {window_s:g} s windows", {"window": window_s}))
    if horizon is not None:
        modes.append((f"{horizon}-step prediction", {"horizon": horizon}))
    modes = modes or [("simulation", {})]
    results = [(label, compare(model, flights, warn=False, **kw)) for label, kw in modes]
    if rrd is not None:
        write_rrd(path=rrd, name=f"compare {model_path.name}", model=model,
                   comparisons=[r for _, r in results])
    if as_json:
        click.echo(json.dumps({"model": str(model_path), "modes": [{
            "mode": label, "overall": fits_json(res), "sessions": [
                {"path": str(p), "fit_percent": dict(zip(res.output_names,
                                                         [float(f) for f in fits], strict=True))}
                for p, fits in zip(sessions, res.fits, strict=True)]}
            for label, res in results],
            "stable": model.is_stable, "predictor_stable": model.predictor_is_stable},
            indent=1))
        return
    con = console()
    for label, res in results:
        rows = [(p.name, f) for p, f in zip(sessions, res.fits, strict=True)]
        con.print(fit_table(title=f"{label}: fit [%]", names=res.output_names,
                             rows=[*rows, ("all", res.fit)] if len(rows) > 1 else rows))
    if not model.predictor_is_stable:
        con.print("[yellow]predictor A - KC is unstable: predictions may diverge[/]")


@main.command()
@click.argument("session", type=click.Path(path_type=Path))
@click.option("--method", type=click.Choice(list(_METHODS)), default="iem", show_default=True)
@click.option("--past", default=60, show_default=True, type=click.IntRange(min=1))
@click.option("--future", default=17, show_default=True, type=click.IntRange(min=2))
@click.option("--show", default=20, show_default=True, type=click.IntRange(min=2),
              help="How many singular values to list.")
@session_options
@JSON_OPTION
def order(session: Path, method: str, past: int, future: int, show: int, as_json: bool,
          **opts: Any) -> None:
    """Singular values of the order-selection SVD and a suggested order (largest gap).

    The suggestion is the n maximising log10(s_n / s_n+1) among the first --show values.

    \b
    Example:
      sysid order flight.h5 --past 60 --future 17
    """
    flights = load_flights([session], opts=opts)
    sv = singular_values(flights, past=past, future=future, method=method)
    head = sv[: min(show, sv.size)]
    with np.errstate(divide="ignore"):
        gaps = np.log10(head[:-1] / np.maximum(head[1:], 1e-300))
    suggested = int(np.argmax(gaps)) + 1
    if as_json:
        click.echo(json.dumps({"session": str(session), "singular_values": sv.tolist(),
                               "suggested_order": suggested}, indent=1))
        return
    con = console()
    table = Table("n", "singular value", "log10 gap to next", title=f"{method} p={past} f={future}")
    for i, s in enumerate(head):
        gap = f"{gaps[i]:.2f}" if i < gaps.size else ""
        table.add_row(str(i + 1), f"{s:.4g}", gap, style="bold" if i + 1 == suggested else None)
    con.print(table)
    con.print(f"suggested order: {suggested}")


@main.command("sweep")
@click.argument("session", type=click.Path(path_type=Path))
@click.option("--method", type=click.Choice(list(_METHODS)), default="iem", show_default=True)
@click.option("--pasts", default="20:80:10", show_default=True, help="START:STOP:STEP or a,b,c.")
@click.option("--futures", default="5:25:4", show_default=True,
              help="START:STOP:STEP or a,b,c (each >= 2).")
@click.option("--orders", default="8", show_default=True, help="START:STOP:STEP or a,b,c.")
@click.option("--workers", default=1, show_default=True, type=click.IntRange(1, 64),
              help="Worker processes (Ctrl-C stops them all).")
@click.option("--validate", "validate", multiple=True, type=click.Path(path_type=Path),
              help="Score on this session (repeatable; default: the identification data).")
@click.option("--horizon", type=click.IntRange(min=1), help="Score by k-step prediction.")
@click.option("--window-s", type=FiniteFloat(min=0, min_open=True),
              help="Score by simulation over windows of this many seconds.")
@click.option("--top", default=10, show_default=True, type=click.IntRange(min=1))
@session_options
@JSON_OPTION
@RRD_OPTION
def sweep_cmd(session: Path, method: str, pasts: str, futures: str, orders: str, workers: int,
              validate: tuple[Path, ...], horizon: int | None, window_s: float | None, top: int,
              as_json: bool, rrd: Path | None, **opts: Any) -> None:
    """Identify a model for every (past, future, order) and rank them by fit.

    Models that cannot be identified are counted with their reasons; when none can, the
    command exits with 2.

    \b
    Example:
      sysid sweep flight.h5 --pasts 20:80:10 --futures 5:25:4 --orders 6,8,10 \\
        --validate other_flight.h5 --window-s 5 --workers 2
    """
    lazy = {"pasts": parse_grid(text=pasts, option="--pasts"),
            "futures": parse_grid(text=futures, option="--futures", minimum=2),
            "orders": parse_grid(text=orders, option="--orders")}
    check_rrd(rrd, inputs=(session, *validate))
    flights = load_flights([session], opts=opts)
    _check_sweep_horizons(flights[0], pasts=lazy["pasts"], futures=lazy["futures"])
    total = len(lazy["pasts"]) * len(lazy["futures"]) * len(lazy["orders"])
    if total > MAX_SWEEP_MODELS:
        raise DataError(f"the grid has {total} models, more than {MAX_SWEEP_MODELS}; use "
                        "coarser steps (START:STOP:STEP) and refine around the best")
    grid = {k: list(v) for k, v in lazy.items()}
    val = load_flights(list(validate), opts=opts) if validate else None
    with Progress("sweep", BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  console=Console(stderr=True), disable=as_json) as bar:
        task = bar.add_task("sweep", total=total)
        result = run_sweep(flights, **grid, method=method.replace("-", "_"), validation=val,
                           horizon=horizon, window=window_s, workers=workers,
                           keep_models=rrd is not None,
                           progress=lambda done, _total: bar.update(task, completed=done))
    ok = sorted((r for r in result.rows if r.error is None and np.isfinite(r.mean_fit)),
                key=lambda r: -r.mean_fit)
    failures = result.failures()
    n_failed = sum(n for _, n in failures)
    try:
        best = result.best()
    except SysIdError:
        best = None
    rrd_written = rrd is not None and best is not None and best.model is not None
    if rrd_written:
        write_rrd(path=rrd, name=f"sweep {session.name}", model=best.model, sweep=result)
    if as_json:
        click.echo(json.dumps({"session": str(session), "n_models": len(result.rows),
                               "n_failed": n_failed,
                               "failures": [{"error": e, "count": n} for e, n in failures],
                               "best": best.to_record() if best else None,
                               "top": [r.to_record() for r in ok[:top]],
                               "rrd": str(rrd) if rrd_written else None}, indent=1))
    else:
        con = console()
        if ok:
            table = Table("past", "future", "order", "mean fit [%]", "max |pole|", "stable",
                          "pred. stable", title=f"best {min(top, len(ok))} of {len(result.rows)} "
                          "models")
            for r in ok[:top]:
                table.add_row(str(r.past), str(r.future), str(r.order), f"{r.mean_fit:.2f}",
                              f"{np.abs(r.poles).max():.4f}", str(r.stable),
                              str(r.predictor_stable))
            con.print(table)
        if failures:
            con.print(f"[yellow]{n_failed} of {len(result.rows)} models failed:[/]")
            for msg, n in failures[:3]:
                con.print(f"  {n} x {msg}", markup=False, soft_wrap=True)
            if len(failures) > 3:
                con.print(f"  ... and {len(failures) - 3} other reasons (--json lists all)")
        if best is not None:
            con.print(f"selected (smallest order within 0.5 points of the best stable fit): "
                      f"past {best.past}, future {best.future}, order {best.order}, "
                      f"fit {best.mean_fit:.2f} %")
        elif ok:
            con.print("[yellow]no stable model in the grid[/]")
    if rrd is not None and not rrd_written:
        click.echo(f"warning: --rrd {rrd} not written: "
                   f"{'no stable model' if ok else 'no model'} to show", err=True)
    if not ok:
        reason = (" (reasons above)" if not as_json else
                  f"; most often: {failures[0][0]}" if failures else "")
        raise DataError(f"none of the {len(result.rows)} models could be identified{reason}")


def _check_sweep_horizons(data: Any, *, pasts: Any, futures: Any) -> None:
    """Refuse horizons the data cannot support before the sweep runs (they would only fail,
    and a huge range would take the memory of every Hankel matrix it tries). One flight of N
    samples and c channels has room for past + future <= (N + 1) / (c + 1)."""
    c = data.n_inputs + data.n_outputs
    room = (data.n_samples + 1) // (c + 1)
    for name, values, other, other_name in (("past", pasts, futures, "future"),
                                            ("future", futures, pasts, "past")):
        largest, shortest = grid_max(values), grid_min(other)
        if largest + shortest > room:
            raise HorizonError(
                f"--{name}s goes up to {largest}, but {data.n_samples} samples with {c} channels "
                f"allow past + future <= {room}: {name} <= {room - shortest} with {other_name} "
                f"{shortest}; lower the {name}s or pass a longer --window")


@main.command()
@click.argument("model_path", metavar="MODEL", type=click.Path(path_type=Path))
@click.option("--format", "fmt", required=True, type=click.Choice(["json", "mat"]))
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="Output file (default: MODEL with the format's suffix).")
@FORCE_OPTION
def export(model_path: Path, fmt: str, out: Path | None, force: bool) -> None:
    """Write a model file as JSON or MATLAB .mat (A, B, C, D, K, Ts, names, units).

    \b
    Example:
      sysid export model.h5 --format mat --out model.mat
    """
    model = load_model(model_path)
    target = out or model_path.with_suffix(f".{fmt}")
    check_output(target, option="--out", suffixes=(f".{fmt}",), inputs=(model_path,),
                 overwrite=force, force_flag="--force")
    model.save(target)
    click.echo(f"wrote {target}")
