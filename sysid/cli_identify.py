"""``sysid identify``: one model from one or more sessions, its horizons and order chosen
by validation unless given (:mod:`sysid.auto`), reported with its poles and fits."""

from __future__ import annotations

import json
import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console
from rich.markup import escape

from cfcommon.cli import check_output, same_file_pairs
from sysid.cli_compare import check_fit_samples
from sysid.cli_options import (
    METHOD_OPTION,
    fixed_option,
    method_chosen,
    method_options,
    model_options,
)
from sysid.cli_support import (
    MODEL_SUFFIXES,
    check_rrd,
    console,
    default_compare_mode,
    fit_or_none,
    fit_table,
    fits_json,
    load_flights,
    load_groups,
    pole_table,
    poles_rich_table,
    write_rrd,
)
from sysid.cli_sweep import choose, print_selection, saved_line, selection_json
from sysid.data import IOData
from sysid.errors import DataError
from sysid.holdout import ORDERS
from sysid.model import StateSpaceModel
from sysid.model_io import check_not_a_session
from sysid.pole_format import pole_number
from sysid.quirks import direction_warnings, frozen_warnings
from sysid.refit import PROVENANCE_KEY
from sysid.validate import below_mean_warning, compare, min_fit_samples

__all__ = ["identify", "samples_line"]

log = logging.getLogger(__name__)


def samples_line(flights: Sequence[IOData], *, dt: float,
                 model: StateSpaceModel | None = None) -> str:
    """How much data the model was identified from: the samples in total and, with several
    experiments, each one's (a session read only as far as its damage shows here too). When
    the model is the one a sweep scored on part of them (its refit on all was not kept,
    :mod:`sysid.refit`), the line says the samples were loaded and what the model used."""
    total = sum(d.n_samples for d in flights)
    entry = model.provenance.get(PROVENANCE_KEY) if model is not None else None
    scored = isinstance(entry, dict) and entry.get("identified_again") is False
    line = (f"{'loaded' if scored else 'identified from'} {total} samples "
            f"({total * dt:.1f} s at dt {dt:g} s)")
    if len(flights) == 1:
        line += f" of {flights[0].source}"
    else:
        each = ", ".join(f"{d.source} {d.n_samples}" for d in flights)
        line += f" in {len(flights)} experiments: {each}"
    return line + (f"; the model is the one the sweep scored, {entry['data']}" if scored else "")


@click.command("identify")
@click.argument("sessions", nargs=-1, required=True, type=click.Path(path_type=Path))
@METHOD_OPTION
@fixed_option("order",
              help="Model order (default: chosen by validation).")
@fixed_option("past",
              help="Past horizon, samples (default: chosen by validation).")
@fixed_option("future",
              help="Future horizon, samples (default: chosen by validation).")
@click.option("--feedthrough/--no-feedthrough", default=None,
              help="Estimate D (default: no for iem, yes for po-moesp and parsim-k; when the "
                   "model is chosen, a direct term is also tried where the data show no "
                   "feedback, and kept when it scores better on held-out data).")
@click.option("--validate", "validate", multiple=True, type=click.Path(path_type=Path),
              help="Score the model on this session (simulation as `sysid compare` scores "
                   "it by default, and 1-step prediction); repeatable.")
@click.option("--workers", default=1, show_default=True, type=click.IntRange(1, 64),
              help="Worker processes for the choice of horizons and order.")
@model_options(out_help="Save the model (.h5, .json or .mat); an existing file needs --force.")
def identify(sessions: tuple[Path, ...], method: str, order: int | None, past: int | None,
             future: int | None, feedthrough: bool | None, validate: tuple[Path, ...],
             workers: int, focus: str | None, stability: str, out: Path | None, force: bool,
             as_json: bool, rrd: Path | None, **opts: Any) -> None:
    """Identify one model from one or more sessions (each its own experiment).

    Without --past/--future/--order they are chosen by validation on held-out data (the
    last session when several are given, else the last 30 % of each experiment; see
    docs/sysid.md): the best candidates are listed with their fits, and a choice at the edge
    of the grid, or held-out data too few to rank the models, is flagged. Without --method,
    PARSIM-K is tried beside IEM at the chosen horizons and the smaller order that scores as
    well wins (IEM on a tie; docs/sysid.md, "Method"). Then prints the
    poles, whether the model and its predictor A - KC are stable, and the fit on the
    identification data and on each --validate session: simulation as `sysid compare` gives
    it by default (over 2 s windows for a model with a pole near the unit circle), and
    one-step prediction. A fit below 0 % on a --validate session is warned of.

    \b
    Examples:
      sysid identify flight.h5 --out model.h5
      sysid identify flight.h5 --order 8 --past 60 --future 17
      sysid identify log00.h5 --validate log01.h5 \\
        --inputs controller.cmd_roll,controller.cmd_pitch,controller.cmd_yaw \\
        --outputs controller.r_roll,controller.r_pitch,controller.r_yaw
    """
    if out is not None:
        check_output(out, option="--out", suffixes=MODEL_SUFFIXES, inputs=sessions,
                     overwrite=force, force_flag="--force")
        check_not_a_session(out)  # before the identification, not after it
    check_rrd(rrd, inputs=(*sessions, *validate), force=force)
    check_sessions_distinct(sessions, validate)
    meth, options = method_options(method, feedthrough=feedthrough, focus=focus,
                                   stability=stability)
    fixed = order is not None and past is not None and future is not None
    # a session's window too short to score on, refused before the search (one session is
    # split, and its refusal says what the split needs: sysid.holdout)
    whole = not fixed and len(sessions) > 1
    groups = load_groups(sessions, opts=opts, elsewhere=validate,
                         min_states=order or ORDERS[0] if whole else None)
    flights = [e for g in groups for e in g]
    selection = None
    if fixed:
        # the selection's cheapest checks, said here (its outlier and drift checks cost more
        # than this fit)
        for warning in [*frozen_warnings(flights), *direction_warnings(flights)]:
            log.warning("%s", warning)
        with Console(stderr=True).status(f"identifying ({method}, n={order})"):
            model = meth.identify(flights, order=order, past=past, future=future,
                                  options=options)
    else:
        given = {key: [value] for key, value in (("pasts", past), ("futures", future),
                                                  ("orders", order)) if value is not None}
        selection = choose(groups, method=meth, options=options, grid=given, workers=workers,
                           choose_focus=focus is None, quiet=as_json,
                           choose_method=method_chosen(),
                           choose_feedthrough="open-loop" if feedthrough is None else False)
        model = selection.model
        order, past, future = selection.best.order, selection.best.past, selection.best.future
    # Simulation as `sysid compare` scores it by default (one rule, one figure: a model with
    # a pole near the unit circle over windows, each from its own initial state, since a
    # quadrotor's rates integrate torque and a whole flight drifts even for a good model).
    sim_label, sim_mode = default_compare_mode(model,
                                               n_samples=min(d.n_samples for d in flights))
    sim = compare(model, flights, warn=False, **sim_mode)
    pred = compare(model, flights, horizon=1, warn=False)
    checks = []
    if validate:
        val = load_flights(list(validate), opts={**opts, "dt": model.dt},
                           inputs=model.input_names, outputs=model.output_names,
                           verb="validate the model on", elsewhere=sessions)
        # records too short to score (the rule `sysid compare` refuses them by) are named and
        # left out; the others are scored; the model is saved either way
        need = min_fit_samples(n_states=model.n_states, n_outputs=model.n_outputs)
        short = [d for d in val if d.n_samples < need]
        try:
            check_fit_samples(model, short, remedy=f"validate on records of "
                              f"{need * model.dt:.3g} s at least")
        except DataError as exc:
            log.warning("validation not scored%s: %s", " on these" if len(short) < len(val)
                        else "", exc)
        val = [d for d in val if d.n_samples >= need]
        if val:
            # `sysid compare MODEL VALIDATION` prints the same simulation figures, and
            # `--horizon 1` the same prediction's
            v_label, v_mode = default_compare_mode(model,
                                                   n_samples=min(d.n_samples for d in val))
            checks = [(f"validation: {v_label}", compare(model, val, warn=False, **v_mode)),
                      ("validation: 1-step prediction",
                       compare(model, val, horizon=1, warn=False))]
            below = below_mean_warning([(label.removeprefix("validation: "), r)
                                        for label, r in checks],
                                       data=", ".join(p.name for p in validate))
            if below:
                log.warning("%s", below)
    if all(fit_or_none(f) is None for f in (*sim.fit, *pred.fit)):  # no use to anyone
        raise DataError(
            f"the model diverges on the data it was identified from (every windowed-simulation "
            f"and 1-step fit; poles up to |z| = {np.abs(model.poles()).max():.3g}): these data "
            f"do not support order {order} with past {past}, future {future}; try a lower "
            "--order, --stability enforce, or no --order/--past/--future for the automatic "
            "choice" + ("; nothing saved" if out is not None else ""))
    if out is not None:
        model.save(out)
    if rrd is not None:
        write_rrd(path=rrd, name=f"identify {sessions[0].name}", model=model,
                  comparisons=[sim, pred], validation=[r for _, r in checks],
                  sweep=selection.result if selection else None)
    poles = pole_table(model)
    method = str(model.provenance.get("method", method))  # the selection may choose it
    if as_json:
        click.echo(json.dumps({
            "sessions": [str(p) for p in sessions], "method": method, "order": order,
            "past": past, "future": future, "n_samples": [d.n_samples for d in flights],
            "experiments": [d.source for d in flights],
            "dt_s": model.dt, "poles": poles, "stable": model.is_stable,
            "predictor_stable": model.predictor_is_stable,
            "fit_percent": {"simulation": fits_json(sim), "1-step": fits_json(pred)},
            "simulation_window_s": sim_mode.get("window"),
            "selection": selection_json(selection) if selection else None,
            "validation": [{"mode": label, "fit_percent": fits_json(r)} for label, r in checks],
            "focus": model.provenance.get("focus"),
            "stability": model.provenance.get("stability"),
            "model": str(out) if out else None}, indent=1))
        return
    con = console()
    con.print(escape(samples_line(flights, dt=model.dt, model=model)))
    if selection is not None:
        print_selection(con, selection)
    con.print(poles_rich_table(
        model, title=f"{method} order {order}, past {past}, future {future}: poles", console=con))
    con.print(f"stable: {model.is_stable} (max |pole| {pole_number(np.abs(model.poles()).max())}); "
              f"predictor A - KC stable: {model.predictor_is_stable}")
    report = model.provenance.get("stability")
    if isinstance(report, dict) and report.get("moved"):
        radii = ", ".join(f"{m['radius_from']:.4f} -> {m['radius_to']:.4f}"
                          for m in report["moved"])
        cost = report.get("cost_points")
        con.print(f"stability={report['mode']}: pole(s) moved {radii}; " + (
            "what it cost not measured" if report.get("measure") is None else
            f"{report['measure']} fit on these data "
            + ("not measurable: the free model diverges" if cost is None
               else f"{-cost:+.2f} points")))
    con.print(fit_table(console=con, title="fit on the identification data [%]",
                        names=model.output_names,
                        rows=[(sim_label, sim.fit),
                              ("1-step prediction", pred.fit)]))
    if checks:
        con.print(fit_table(console=con,
                            title=f"fit on {', '.join(p.name for p in validate)} [%]",
                            names=model.output_names, rows=[(k, r.fit) for k, r in checks]))
    if out is not None:
        con.print(saved_line(out, model))
    else:  # a long identification shown and then lost is a surprise: say it
        con.print("model not saved: --out FILE.h5 saves it (sysid compare, export and the "
                  "Python API read it)")


def check_sessions_distinct(sessions: Sequence[Path], validate: Sequence[Path]) -> None:
    """Refuse a session given twice (its experiments would count twice, and the last session
    is the held-out one); warn, once, when a --validate session is one identified from (its
    fits are then on the identification data, no check of the model)."""
    twice = same_file_pairs(sessions)
    if twice:
        first, again = twice[0]
        also = "" if str(first) == str(again) else f" (as {first})"
        raise click.BadParameter(f"{again} is given twice{also}: one flight would count as "
                                 "two experiments (and be held out to validate the models "
                                 "it chose); give each session once", param_hint="SESSIONS")
    both = same_file_pairs(validate, sessions)
    if both:
        names = ", ".join(dict.fromkeys(str(v) for v, _ in both))
        log.warning("--validate %s is also identified from: its fits are on the "
                    "identification data, not a check of the model; validate on another "
                    "flight of the same kind", names)
