"""``sysid sweep``, and the choice of horizons, order and focus it shares with ``identify``.

Both commands choose through :func:`choose` (:func:`sysid.auto.select_plan` with progress on
stderr), so on the same data and grid they choose the same past, future, order and focus, and
both report the choice with :func:`print_selection` / :func:`selection_json`. The sweep adds
grid options (--pasts/--futures/--orders, checked before anything runs), the reasons its
models failed, and --out for the selected model.
"""

from __future__ import annotations

import contextlib
import json
import math
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any, Literal

import click
import numpy as np
from rich.console import Console

from cfcommon.cli import check_output, output_table
from sysid.auto import (
    NoStableModel,
    Selection,
    default_grid,
    holdout,
    max_blocks,
    n_runs,
    plan,
    select_plan,
)
from sysid.cli_progress import progress
from sysid.cli_support import (
    MODEL_SUFFIXES,
    check_rrd,
    console,
    fit_cell,
    grid_max,
    grid_min,
    load_flights,
    load_groups,
    parse_grid,
    write_rrd,
)
from sysid.data import IOData
from sysid.errors import DataError, HorizonError
from sysid.holdout import GIVE_HORIZONS, ORDERS, VALIDATE_WITH
from sysid.methods import Method, Options
from sysid.model import StateSpaceModel
from sysid.model_io import MAX_DIMENSION, check_not_a_session
from sysid.refit import saved_as
from sysid.sweep import SweepRow
from sysid.variants import ALTERNATIVE

__all__ = ["MAX_SWEEP_MODELS", "check_sweep_horizons", "choose", "print_selection",
           "saved_line", "selection_json", "sweep_command"]

#: Largest sweep grid accepted (models); the thesis' coarse-to-fine search was 756 models.
MAX_SWEEP_MODELS = 100_000
#: Candidates `identify` lists.
TOP = 8
#: What a record too short for the default grid asks `sweep` for (its options).
SWEEP_GIVE = "ranges of horizons (--pasts/--futures, and --orders)"
SWEEP_VALIDATE = "a validation session (--validate)"

Connect = Callable[[], AbstractContextManager[Any]]


def choose(groups: Sequence[Sequence[IOData]], *, method: Method, options: Options,
           grid: dict[str, list[int]] | None = None,
           validation: Sequence[IOData] | None = None, choose_focus: bool = False,
           choose_feedthrough: bool | Literal["open-loop"] = False,
           choose_method: bool = False,
           horizon: int | None = None, window: float | None = None, workers: int = 1,
           connect: Connect | None = None, quiet: bool = False, label: str | None = None,
           give: str = GIVE_HORIZONS, validate_with: str = VALIDATE_WITH) -> Selection:
    """:func:`sysid.auto.plan` and :func:`sysid.auto.select_plan` with a progress bar
    (``label``) over every focus run; ``connect()`` opens the Dask client (None: run here).
    ``give``, ``validate_with``: the command's options for horizons and for validation data,
    named when the records are too short for the default grid
    (:func:`sysid.holdout.default_grid`).
    Raises :class:`sysid.auto.NoStableModel` when no model of the grid is stable."""
    p = plan(groups, validation=validation, give=give, validate_with=validate_with,
             **(grid or {}))
    if p.n_models > MAX_SWEEP_MODELS:
        raise DataError(f"the grid has {p.n_models} models, more than {MAX_SWEEP_MODELS}; use "
                        "coarser steps (START:STOP:STEP) and refine around the best")
    total = p.n_models * n_runs(options, choose_focus=choose_focus) + (
        len(p.grid["orders"]) if choose_method and method.name in ALTERNATIVE else 0)
    label = label or "choosing horizons, order" + (" and focus" if choose_focus else "")
    with (connect or contextlib.nullcontext)() as client, \
            progress(label, total=total, quiet=quiet) as update:
        return select_plan(p, method=method, options=options, workers=workers,
                           choose_focus=choose_focus, choose_feedthrough=choose_feedthrough,
                           choose_method=choose_method, horizon=horizon, window=window,
                           client=client, progress=update)


def _span(values: Sequence[int]) -> str:
    """``2..12`` for a run of whole numbers, else the list: ``[6, 8]``."""
    values = list(values)
    if len(values) > 2 and values == list(range(values[0], values[-1] + 1)):
        return f"{values[0]}..{values[-1]}"
    return str(values)


def _candidates(con: Console, rows: Sequence[SweepRow], *, names: Sequence[str], title: str,
                chosen: SweepRow | None = None) -> None:
    table = output_table("past", "future", "order", "score [%]", *names, "max |pole|", "stable",
                         console=con, title=title)
    for r in rows:
        table.add_row(str(r.past), str(r.future), str(r.order), f"{r.score:.1f}",
                      *[fit_cell(f) for f in r.fit],
                      f"{np.abs(r.poles).max():.4f}" if r.poles.size else "-", str(r.stable),
                      style="bold" if r is chosen else None)
    con.print(table)


def print_selection(con: Console, sel: Selection, *, top: int = TOP) -> None:
    """The best ``top`` candidates with their per-channel fits, the split and grid, what was
    chosen and why, and warnings (a choice at the grid's edge, channels no candidate
    predicts)."""
    names = sel.model.output_names
    rows = sel.top(top)
    shown = min(top, len(sel.result.ranked()))
    # the progress counted every model identified: each focus's grid, PARSIM-K's orders
    of = (" with the chosen focus (the progress counted both focuses' grids)"
          if len(sel.focus_scores or {}) > 1 else "")
    _candidates(con, rows, names=names, chosen=sel.best,
                title=f"best {shown} candidates of {len(sel.result.rows)}{of}"
                      + ("" if len(rows) == shown else
                         f" and the chosen one (last, {sel.model.provenance.get('method')})")
                      + f" (fit [%], {sel.scoring} of held-out data)")
    dt = sel.model.dt
    con.print(f"{sel.rule}; grid pasts {sel.grid['pasts']}, futures {sel.grid['futures']}, "
              f"orders {_span(sel.grid['orders'])}"
              + ("" if sel.memory is None else
                 f" (horizons from the data's memory of {sel.memory} samples, the lag of the "
                 "best ARX model by AICc)"))
    con.print(f"chosen: past {sel.best.past} ({sel.best.past * dt:.2f} s), future "
              f"{sel.best.future} ({sel.best.future * dt:.2f} s), order {sel.best.order}, "
              f"method {sel.model.provenance.get('method')}, "
              f"focus {sel.model.provenance.get('focus')}: the smallest order within "
              + ("0.5 points" if sel.tolerance is None else
                 f"{sel.tolerance:.2f} points ({sel.tolerance_basis})")
              + " of the best stable score (score = mean fit with each channel floored at 0 %)")
    for note in (sel.feedback.describe() if sel.feedback else "", sel.focus_note,
                 sel.feedthrough_note, sel.method_note, slow_mode_note(sel)):
        if note:
            con.print(note)
    for w in sel.warnings:
        con.print(f"[yellow]warning: {w}[/]")
    bad = [n for i, n in enumerate(names) if max(r.fit[i] for r in rows) <= 0]
    if bad:
        con.print(f"[yellow]no candidate predicts {', '.join(bad)} (fit <= 0 %): consider "
                  "dropping it from --outputs[/]")


def slowest_time_constant(sel: Selection) -> float | None:
    """The chosen model's slowest time constant ``-dt / ln|z|``, seconds (None without poles;
    ``inf`` for a pole on the unit circle)."""
    poles = np.abs(sel.model.poles())
    if not poles.size:
        return None
    slowest = float(np.max(poles))
    return math.inf if slowest >= 1.0 else -sel.model.dt / math.log(max(slowest, 1e-300))


def slow_mode_note(sel: Selection) -> str:
    """What the held-out score does not check: the chosen model's slowest mode when it is
    slower than the scoring windows (a near-integrating plant, a slow drift). The score
    simulates each window from its own fitted initial state, so it sees the model's response
    above about 1 / window Hz and not its gain below: on closed-loop data the measured input
    is the controller's answer to the integrated disturbance, and models whose low-frequency
    gains differ several times score alike (the true plant may score below a wrong one).
    Empty when the mode is faster than the windows."""
    tau, window = slowest_time_constant(sel), sel.window_s
    if tau is None or window is None or tau <= window:
        return ""
    slow = "an integrator" if math.isinf(tau) else f"time constant {tau:.3g} s"
    return (f"slowest mode: {slow}, longer than the {window:.3g} s scoring windows: the "
            f"held-out score checks the model above about {1 / window:.2g} Hz, not its gain "
            "below (in closed loop the data may not fix it); `sysid compare --window-s` with "
            "longer windows on another flight shows more there")


def selection_json(sel: Selection, *, top: int = TOP) -> dict[str, Any]:
    """What was chosen and why, JSON-able (``candidates``: the best ``top``)."""
    return {"rule": sel.rule, "score": "mean of per-channel fits floored at 0 %, "
            f"{sel.scoring} of the validation data",
            "grid": sel.grid, "memory_samples": sel.memory,
            "tolerance_points": sel.tolerance, "tolerance_basis": sel.tolerance_basis,
            "chosen": sel.best.to_record(), "warnings": list(sel.warnings),
            "focus": sel.model.provenance.get("focus"), "focus_note": sel.focus_note,
            "focus_scores": sel.focus_scores, "feedthrough_note": sel.feedthrough_note,
            "method": sel.model.provenance.get("method"), "method_note": sel.method_note,
            "feedback": None if sel.feedback is None else {
                "found": sel.feedback.feedback, "lags": sel.feedback.lags,
                "p_values": dict(zip(sel.feedback.input_names,
                                     map(float, sel.feedback.p_values), strict=True)),
                "note": sel.feedback.describe()},
            "slowest_time_constant_s": _json_number(slowest_time_constant(sel)),
            "score_window_s": sel.window_s, "slow_mode_note": slow_mode_note(sel),
            "candidates": [r.to_record() for r in sel.top(top)]}


def _json_number(value: float | None) -> float | str | None:
    """A number for JSON: ``"inf"`` for infinity (JSON has none)."""
    return "inf" if value is not None and math.isinf(value) else value


def sweep_command(*, session: Path, method: Method, options: Options, choose_focus: bool,
                  choose_feedthrough: bool | Literal["open-loop"] = False,
                  choose_method: bool = False,
                  pasts: str | None, futures: str | None, orders: str | None, workers: int,
                  connect: Connect, validate: tuple[Path, ...], horizon: int | None,
                  window_s: float | None, top: int, out: Path | None, force: bool,
                  as_json: bool, rrd: Path | None, opts: dict[str, Any]) -> None:
    """The body of ``sysid sweep`` (its options and help are in :mod:`sysid.cli`)."""
    lazy = {k: parse_grid(text=v, option=f"--{k}", minimum=2 if k == "futures" else 1,
                          maximum=MAX_DIMENSION if k == "orders" else None)  # a model file's
            for k, v in (("pasts", pasts), ("futures", futures), ("orders", orders))
            if v is not None}
    if out is not None:
        check_output(out, option="--out", suffixes=MODEL_SUFFIXES, inputs=(session, *validate),
                     overwrite=force, force_flag="--force")
        check_not_a_session(out)  # before the sweep, not after it
    check_rrd(rrd, inputs=(session, *validate), force=force)
    # the smallest candidate's order: a window too short to score it on is refused before the
    # sweep (one session without --validate is split, and its refusal says what the split
    # needs: sysid.holdout)
    smallest = grid_min(lazy["orders"]) if "orders" in lazy else ORDERS[0]
    groups = load_groups([session], opts=opts, elsewhere=validate,
                         min_states=smallest if validate else None)
    val = (load_flights(list(validate), opts={**opts, "dt": groups[0][0].dt},  # its grid
                        verb="validate the models on", elsewhere=[session],
                        min_states=smallest) if validate else None)
    if "pasts" in lazy or "futures" in lazy:
        ident = groups[0] if val else holdout(groups)[0]
        # the default grid (and the memory it takes) only for what was not given
        default = {} if "pasts" in lazy and "futures" in lazy else default_grid(
            ident, groups=None if val else groups, give=SWEEP_GIVE,
            validate_with=SWEEP_VALIDATE)
        check_sweep_horizons(ident, pasts=lazy.get("pasts") or default["pasts"],
                             futures=lazy.get("futures") or default["futures"])
    total = int(np.prod([len(v) for v in lazy.values()], dtype=float))
    if total > MAX_SWEEP_MODELS:  # before the lazy ranges become lists
        raise DataError(f"the grid has {total} models, more than {MAX_SWEEP_MODELS}; use "
                        "coarser steps (START:STOP:STEP) and refine around the best")
    sel: Selection | None = None
    try:
        sel = choose(groups, method=method, options=options,
                     grid={k: list(v) for k, v in lazy.items()}, validation=val,
                     choose_focus=choose_focus, choose_feedthrough=choose_feedthrough,
                     choose_method=choose_method, horizon=horizon, window=window_s,
                     workers=workers, connect=connect, quiet=as_json, label="sweep",
                     give=SWEEP_GIVE, validate_with=SWEEP_VALIDATE)
        result, rule, grid = sel.result, sel.rule, sel.grid
    except NoStableModel as exc:  # report the grid of the method's default focus anyway
        result, rule, grid = exc.results[0], exc.plan.rule, exc.plan.grid
    names = groups[0][0].output_names or ()
    ok = result.ranked()
    failures = result.failures()
    n_failed = sum(n for _, n in failures)
    if out is not None and sel is not None:
        sel.model.save(out)
    if rrd is not None and sel is not None:
        write_rrd(path=rrd, name=f"sweep {session.name}", model=sel.model, sweep=result)
    if as_json:
        chosen = selection_json(sel, top=top) if sel is not None else {
            "rule": rule, "grid": grid, "chosen": None, "warnings": [], "focus": None,
            "focus_note": "", "focus_scores": None, "method": None, "method_note": ""}
        chosen.pop("candidates", None)  # listed as "top"
        click.echo(json.dumps({
            "session": str(session), "n_models": len(result.rows), "n_failed": n_failed,
            "failures": [{"error": e, "count": n} for e, n in failures], **chosen,
            "best": chosen["chosen"],
            "top": [r.to_record() for r in (sel.top(top) if sel is not None else ok[:top])],
            "model": str(out) if out and sel else None,
            "rrd": str(rrd) if rrd and sel else None}, indent=1))
    else:
        con = console()
        if sel is not None:
            print_selection(con, sel, top=top)
        elif ok:
            _candidates(con, ok[:top], names=names,
                        title=f"best {min(top, len(ok))} of {len(result.rows)} models (none "
                              f"stable; fit [%], {result.scoring} of held-out data)")
            con.print(rule)
        if failures:
            con.print(f"[yellow]{n_failed} of {len(result.rows)} models failed:[/]")
            for msg, n in failures[:3]:
                con.print(f"  {n} x {msg}", markup=False, soft_wrap=True)
            if len(failures) > 3:
                con.print(f"  ... and {len(failures) - 3} other reasons (--json lists all)")
        if out is not None and sel is not None:
            con.print(saved_line(out, sel.model))
    if rrd is not None and sel is None:
        click.echo(f"warning: --rrd {rrd} not written: "
                   f"{'no stable model' if ok else 'no model'} to show", err=True)
    if not ok:
        reason = (" (reasons above)" if not as_json else
                  f"; most often: {failures[0][0]}" if failures else "")
        raise DataError(f"none of the {len(result.rows)} models could be identified{reason}")
    if sel is None:
        raise DataError(f"none of the {len(ok)} identified models is stable"
                        + (" with either focus" if choose_focus else "")
                        + "; widen the grid or pick other channels")


def saved_line(out: Path, model: StateSpaceModel) -> str:
    """"model saved to OUT (what it is)": identified again on all the data, or the model the
    sweep scored when that refit was not kept (:func:`sysid.refit.saved_as`)."""
    what = saved_as(model)
    return f"model saved to {out}" + (f" ({what})" if what else "")


def check_sweep_horizons(flights: Sequence[IOData], *, pasts: Any, futures: Any) -> None:
    """Refuse horizons the data cannot support before the sweep runs: every pair shares the
    Hankel columns of the largest, which needs ``B c`` columns for ``B = past + future``
    block rows and c channels, so the largest past + future must fit the data."""
    c = flights[0].n_inputs + flights[0].n_outputs
    room = max_blocks(flights, columns_per_row=1.0)
    n = max(d.n_samples for d in flights)
    for name, values, other, other_name in (("past", pasts, futures, "future"),
                                            ("future", futures, pasts, "past")):
        largest, shortest = grid_max(values), grid_min(other)
        if largest + shortest > room:
            raise HorizonError(
                f"--{name}s goes up to {largest}, but {n} identification samples with {c} "
                f"channels allow past + future <= {room}: {name} <= "
                f"{max(room - shortest, 0)} with {other_name} {shortest}; "
                f"lower the {name}s or pass a longer --window")
    if grid_max(pasts) + grid_max(futures) > room:
        raise HorizonError(
            f"--pasts up to {grid_max(pasts)} with --futures up to {grid_max(futures)}: every "
            f"pair shares the columns of the largest, but {n} identification samples with {c} "
            f"channels allow past + future <= {room}; lower the largest past or future")
