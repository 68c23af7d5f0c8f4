"""``sysid compare`` and ``sysid resid``: a model against sessions it was not identified on.

``compare`` gives the fit per channel and per session (simulation, windowed simulation or k-step
prediction, :func:`sysid.validate.compare`); ``resid`` the residual analysis
(:func:`sysid.residuals.residuals`). Both read the sessions on the model's grid and channels and
can write a Rerun report. Registered on the ``sysid`` group by :mod:`sysid.cli`.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import click
import numpy as np

from cfcommon.cli import FiniteFloat, output_console
from sysid.cli_support import (
    DETREND_OPTION,
    JSON_OPTION,
    MAX_WINDOW_S,
    RRD_FORCE_OPTION,
    RRD_OPTION,
    WINDOW_HELP,
    check_rrd,
    console,
    default_compare_mode,
    experiment_label,
    fit_table,
    fits_json,
    load_flights,
    load_model_arg,
    pole_kind,
    write_rrd,
)
from sysid.data import IOData
from sysid.errors import DataError
from sysid.model import StateSpaceModel
from sysid.pole_format import pole_number
from sysid.residuals import ResidualResult, residuals
from sysid.validate import (
    MIN_WINDOW_SAMPLES,
    SAMPLES_PER_STATE,
    below_mean_warning,
    compare,
    min_fit_samples,
)

__all__ = ["check_fit_samples", "compare_cmd", "echo_residuals", "resid"]

log = logging.getLogger(__name__)


@click.command("compare")
@click.argument("model_path", metavar="MODEL", type=click.Path(path_type=Path))
@click.argument("sessions", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--horizon", type=click.IntRange(min=1), help="k-step-ahead prediction.")
@click.option("--window-s", type=FiniteFloat(min=0, min_open=True, max=MAX_WINDOW_S),
              help="Simulate over windows of this many seconds, each from its own x0.")
@click.option("--window", "windows", multiple=True, default=("auto",), show_default=True,
              help=WINDOW_HELP)
@DETREND_OPTION
@click.option("--residuals", "with_residuals", is_flag=True,
              help="Also print the residual analysis (as `sysid resid`).")
@JSON_OPTION
@RRD_OPTION
@RRD_FORCE_OPTION
def compare_cmd(model_path: Path, sessions: tuple[Path, ...], horizon: int | None,
                window_s: float | None, with_residuals: bool, as_json: bool, rrd: Path | None,
                force: bool, **opts: Any) -> None:
    """Fit of a model on sessions: per channel and per session, in percent (NRMSE).

    The model's channel names select the session channels and its dt sets the grid. Without
    --horizon/--window-s the whole window is simulated from a least-squares initial state,
    unless the model has a pole at |z| >= 0.995 (an integrator, or an unstable or lightly
    damped mode): whole-flight simulation then only measures its drift or growth, so it is
    simulated over 2 s windows (at least 10 output values per state of the initial state
    fitted on each; at most the shortest record, which the table's title then says), and a
    note on stderr names the pole. A record (--window), or a --window-s, with fewer samples
    than that floor (20, and 10 output values per state) is refused: the initial state
    alone would fit it. A fit that diverged is "diverged" in tables and null in --json.
    Each experiment of a session (e.g. its airborne-N phases) is its own row.

    \b
    Example:
      sysid compare model.h5 val1.h5 val2.h5 --window-s 5 --horizon 10
    """
    check_rrd(rrd, inputs=(model_path, *sessions), force=force)
    model = load_model_arg(model_path, sessions, command="compare")
    flights = load_flights(sessions, opts={**opts, "dt": model.dt}, inputs=model.input_names,
                           outputs=model.output_names, verb="compare the model on")
    check_fit_samples(model, flights, window_s=window_s)
    modes: list[tuple[str, dict[str, Any]]] = []
    longest = max(d.n_samples for d in flights)  # beyond it: the whole record is simulated
    shortest = min(d.n_samples for d in flights)
    if window_s is not None:
        win = round(window_s / model.dt)
        whole = (" (longer than the records: each simulated whole)" if win >= longest else
                 " (longer than some records: those simulated whole)" if win >= shortest
                 else "")
        modes.append((f"simulation, {window_s:g} s windows{whole}", {"window": window_s}))
    if horizon is not None:
        whole = (f" (beyond the {longest}-sample records: simulation)"
                 if horizon >= longest else "")
        modes.append((f"{horizon}-step prediction{whole}", {"horizon": horizon}))
    if not modes:
        modes = [default_compare_mode(model, n_samples=shortest)]
        if "windows" in modes[0][0]:
            poles = model.poles()
            pole = complex(poles[int(np.argmax(np.abs(poles)))])
            output_console(stderr=True).print(
                f"model has a pole at |z| = {pole_number(abs(pole))} ({pole_kind(pole)}): "
                f"{modes[0][0]}, each from its own x0; --window-s or --horizon choose "
                "another mode", style="dim")
    results = [(label, compare(model, flights, warn=False, **kw)) for label, kw in modes]
    if below := below_mean_warning(results, data=", ".join(p.name for p in sessions)):
        log.warning("%s", below)
    analysis = residuals(model, flights) if with_residuals else None
    if rrd is not None:
        write_rrd(path=rrd, name=f"compare {model_path.name}", model=model,
                   comparisons=[r for _, r in results], residuals=analysis)
    if as_json:
        click.echo(json.dumps({"model": str(model_path), "modes": [{
            "mode": label, "overall": fits_json(res), "sessions": [
                {"path": d.source, "fit_percent": fits_json(res, fits)}
                for d, fits in zip(flights, res.fits, strict=True)]}
            for label, res in results],
            "stable": model.is_stable, "predictor_stable": model.predictor_is_stable,
            **({} if analysis is None else {"residuals": analysis.to_json()})},
            indent=1))
        return
    con = console()
    for label, res in results:
        rows = [(experiment_label(d.source), f) for d, f in zip(flights, res.fits, strict=True)]
        con.print(fit_table(console=con, title=f"{label}: fit [%]", names=res.output_names,
                             rows=[*rows, ("all", res.fit)] if len(rows) > 1 else rows))
    if not model.predictor_is_stable:
        con.print("[yellow]predictor A - KC is unstable: predictions may diverge[/]")
    if analysis is not None:
        echo_residuals(analysis)


def check_fit_samples(model: StateSpaceModel, flights: list[IOData], *,
                      window_s: float | None = None, remedy: str | None = None) -> None:
    """Refuse records, or --window-s windows, too short for a fit to mean anything: every
    mode fits an initial state of ``model.n_states`` parameters to each record (each window),
    and on fewer than :func:`sysid.validate.min_fit_samples` samples (the rule of the default
    windows) that state alone fits them, so every score comes out near 100 %. ``remedy``
    replaces the advice for a short record (default: ``compare``'s longer --window)."""
    need = min_fit_samples(n_states=model.n_states, n_outputs=model.n_outputs)
    why = (f"the initial state of a {model.n_states}-state model on {model.n_outputs} "
           f"output(s) needs at least {need} ({SAMPLES_PER_STATE} output values per state, "
           f"at least {MIN_WINDOW_SAMPLES} samples)")
    short = [d for d in flights if d.n_samples < need]
    if short:
        first = short[0]
        others = f" (and {len(short) - 1} other record(s))" if len(short) > 1 else ""
        remedy = remedy or f"choose a longer --window ({need * model.dt:.3g} s at least)"
        raise DataError(f"{experiment_label(first.source)} has {first.n_samples} samples in "
                        f"its window{others}, too few to score a model on: {why}; {remedy}")
    if window_s is not None and round(window_s / model.dt) < need:
        raise DataError(f"--window-s {window_s:g} is {round(window_s / model.dt)} samples of "
                        f"{model.dt:g} s, too few to score a model on: {why} per window; use "
                        f"--window-s {need * model.dt:.3g} or longer")


@click.command("resid")
@click.argument("model_path", metavar="MODEL", type=click.Path(path_type=Path))
@click.argument("sessions", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--max-lag", default=25, show_default=True, type=click.IntRange(min=1),
              help="Largest correlation lag, samples.")
@click.option("--confidence", default=0.99, show_default=True,
              type=FiniteFloat(min=0.5, max=0.9999, min_open=True),
              help="Confidence of the bounds and verdicts.")
@click.option("--window", "windows", multiple=True, default=("auto",), show_default=True,
              help=WINDOW_HELP)
@DETREND_OPTION
@JSON_OPTION
@RRD_OPTION
@RRD_FORCE_OPTION
def resid(model_path: Path, sessions: tuple[Path, ...], max_lag: int, confidence: float,
          as_json: bool, rrd: Path | None, force: bool, **opts: Any) -> None:
    """Residual analysis: whiteness of the one-step errors and their correlation with inputs.

    Per output: the autocorrelation at lags 1..--max-lag against +-z/sqrt(N) and a Ljung-Box
    test (white?), and the cross-correlation with each input at positive lags (past inputs)
    with a portmanteau test (independent?). Flights are analysed separately and pooled.
    See docs/sysid.md, "Residual analysis".

    \b
    Example:
      sysid resid model.h5 val1.h5 val2.h5 --max-lag 30
    """
    check_rrd(rrd, inputs=(model_path, *sessions), force=force)
    model = load_model_arg(model_path, sessions, command="resid")
    flights = load_flights(sessions, opts={**opts, "dt": model.dt}, inputs=model.input_names,
                           outputs=model.output_names, verb="analyse the residuals on")
    res = residuals(model, flights, max_lag=max_lag, confidence=confidence)
    if rrd is not None:
        write_rrd(path=rrd, name=f"resid {model_path.name}", model=model, residuals=res)
    if as_json:
        click.echo(json.dumps({"model": str(model_path), **res.to_json()}, indent=1))
        return
    echo_residuals(res)


def echo_residuals(res: ResidualResult) -> None:
    """The residual analysis as ``resid`` and ``compare --residuals`` print it: the table,
    then the legend of its columns (:meth:`~sysid.residuals.ResidualResult.legend`)."""
    click.echo(res.summary())
    click.echo(res.legend())
