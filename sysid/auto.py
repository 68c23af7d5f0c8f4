"""Choosing past, future and order by validation on held-out data (no knobs).

**Held-out rule and default grid**: :mod:`sysid.holdout` (:func:`plan`).

**Focus and direct term** (:mod:`sysid.variants`): when the caller does not fix the focus, the
grid runs with both and the method's default wins unless the other scores better by more than
one standard error; for open-loop data (``choose_feedthrough``) once more with a direct term.

**Choice** (:func:`select`): every model of the grid (one factorization, :mod:`sysid.sweep`) is
scored by simulation over windows of :data:`SCORE_WINDOW_X` times the data's memory (in
samples, so the choice does not depend on the sample time; at least 20 samples and 10 output
values per state of the initial state fitted on each, at most the shortest held-out record
long enough for that; shorter ones are left out of the score, :func:`sysid.holdout.plan`)
on the held-out data, ranked by the floored mean fit (:attr:`sysid.sweep.SweepRow.score`),
and the parsimonious best stable model is taken (:meth:`sysid.sweep.SweepResult.best`: the
smallest order within one standard error of the best score, :mod:`sysid.parsimony`). A choice
at the edge of the grid (largest or smallest past, future or order tried, when more than one
was) is flagged when no row inside the grid in that parameter scores within that tolerance of
the best (the score still rises towards the edge; on a flat top the edge says nothing; in
values the caller gave, never grown, also when it scores better than the next value inside:
:func:`sysid.parsimony.rising_edges`, the warning naming the option to extend), and a
warning says when that standard error is a point or more (held-out data too few to rank the
models). Where the caller did not fix the grid, an edge that binds is followed: the grid grows
past it and is swept again with the chosen focus and direct term (:mod:`sysid.growth`, at
most twice); the warning stays only for an edge still binding after that.
**Method** (``choose_method``, :func:`sysid.variants.pick_method`): PARSIM-K is swept at the
chosen horizons with the chosen focus and direct term, and the smaller order within the
tolerance of the best score of either method wins (IEM on a tie).
The chosen horizons and order are then identified again on all the data. ``sysid identify``
(without horizons and order) and ``sysid sweep`` both run :func:`select_plan`, so on the
same data and grid they choose the same past, future, order and focus.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from sysid.data import IOData
from sysid.errors import DataError
from sysid.feedback import FeedbackTest, feedback_test
from sysid.growth import follow_edges
from sysid.holdout import (
    HOLDOUT_FRACTION,
    MIN_COLUMNS_PER_ROW,
    SCORE_WINDOW_X,
    Plan,
    default_grid,
    holdout,
    max_blocks,
    memory_future,
    plan,
    unexcited_warning,
)
from sysid.iem import without_input_warning
from sysid.methods import Method, Options, get_method
from sysid.model import StateSpaceModel
from sysid.parsimony import (
    close_to_best,
    edge_warnings,
    ranking_warning,
    tolerance,
    tolerance_basis,
)
from sysid.quirks import data_warnings
from sysid.refit import final_model
from sysid.sweep import SweepResult, SweepRow, sweep
from sysid.variants import (
    ALTERNATIVE,
    biased_choices,
    focus_order,
    n_runs,
    pick_feedthrough,
    pick_focus,
    pick_method,
    tries_feedthrough,
)

__all__ = ["HOLDOUT_FRACTION", "MIN_COLUMNS_PER_ROW", "SCORE_WINDOW_X", "NoStableModel", "Plan",
           "Selection", "default_grid", "finish", "focus_order", "holdout", "max_blocks",
           "memory_future", "n_runs",
           "pick_feedthrough", "pick_focus", "plan", "select", "select_plan"]

log = logging.getLogger(__name__)

@dataclass(frozen=True, eq=False)
class Selection:
    """What :func:`select` chose and why."""

    best: SweepRow
    result: SweepResult
    model: StateSpaceModel
    rule: str
    window_s: float | None
    warnings: tuple[str, ...]
    grid: dict[str, list[int]]
    focus_note: str = ""
    memory: int | None = None
    focus_scores: dict[str, float] | None = None
    feedthrough_note: str = ""
    method_note: str = ""
    tolerance: float | None = None
    tolerance_basis: str = "one standard error"
    feedback: FeedbackTest | None = None

    def top(self, count: int = 8) -> list[SweepRow]:
        """The best ``count`` models by score, and the chosen one after them when it is not
        among them (a smaller order within the tolerance of the best can rank lower)."""
        rows = self.result.ranked()[:count]
        return rows if any(r is self.best for r in rows) else [*rows, self.best]

    @property
    def scoring(self) -> str:
        """How the candidates were scored (:attr:`sysid.sweep.SweepResult.scoring`)."""
        return self.result.scoring


def finish(p: Plan, result: SweepResult, *, method: Method, options: Options) -> Selection:
    """The parsimonious best stable model of ``result``, flagged at the grid's edges, and
    identified again on all the data (on the identification data when validation was given;
    stable whenever the chosen row was: :func:`sysid.refit.final_model`)."""
    best = result.best()
    ranked = result.ranked(require_stable=True)
    tol, basis = tolerance(ranked[0]), tolerance_basis(ranked[0])
    log.info("selection: best held-out score %.2f, tolerance %.2f points (%s, %s blocks); "
             "orders within it: %s", ranked[0].score, tol, basis,
             "?" if ranked[0].errors is None else ranked[0].errors.shape[0],
             sorted({r.order for r in close_to_best(ranked)}))
    warnings = edge_warnings(best, ranked, p.grid, capped=p.capped,
                             n_outputs=p.ident[0].n_outputs, given=p.fixed)
    # held-out inputs that do not move rank nothing: that is the warning, whatever the scores
    unresolved = unexcited_warning(p) or ranking_warning(
        ranked, n_samples=sum(d.n_samples for d in p.val), validation_given=p.given_validation)
    if unresolved is not None:
        warnings.append(unresolved)
    model = final_model(p, best, warnings, method=method, options=options)
    for w in warnings:
        log.info("selection: %s", w)
    return Selection(best=best, result=result, model=model, rule=p.rule, window_s=result.window,
                     warnings=tuple(warnings), grid=p.grid, memory=p.memory, tolerance=tol,
                     tolerance_basis=basis)


class NoStableModel(DataError):
    """:func:`select` found no stable model (with either focus); ``results`` holds the sweep
    of each focus run (the method's default focus first) and ``plan`` the data and grid, so
    a caller can still report the grid and why its models failed."""

    def __init__(self, message: str, *, plan: Plan, results: Sequence[SweepResult]) -> None:
        super().__init__(message)
        self.plan = plan
        self.results = tuple(results)


def _no_stable(p: Plan, results: Sequence[SweepResult], *, either_focus: bool) -> NoStableModel:
    """Why a grid gave no model to choose: every model failed (the commonest reason), or none
    is stable; the advice fits what the caller fixed."""
    failed: Counter[str] = Counter()
    for result in results:
        failed.update(dict(result.failures()))
    n_all = sum(len(result.rows) for result in results)
    if failed and failed.total() == n_all:  # none was identified: say why (two commonest)
        reasons = failed.most_common(2)
        why = (f": {reasons[0][0]}" if reasons[0][1] == n_all else " (" + "; ".join(
            f"{n} of them: {text}" for text, n in reasons) + ")")
        return NoStableModel(f"all {n_all} models of the grid failed{why}", plan=p,
                             results=results)
    fixed_all = {"pasts", "futures", "orders"} <= set(p.fixed)
    advice = ("other horizons or order, another method (--method), other channels or a longer "
              "window" if fixed_all else "give horizons and an order (--past/--future/--order), "
              "other channels or a longer window")
    return NoStableModel(f"none of the {n_all} models of the grid is stable"
                         + (", with either focus" if either_focus else "") + f"; {advice}",
                         plan=p, results=results)


def select(groups: Sequence[Sequence[IOData]], *, method: Method, options: Options,
           pasts: Sequence[int] | None = None, futures: Sequence[int] | None = None,
           orders: Sequence[int] | None = None, validation: Sequence[IOData] | None = None,
           workers: int = 1, progress: Callable[[int, int], None] | None = None,
           keep_models: bool = False, choose_focus: bool = False,
           choose_feedthrough: bool | Literal["open-loop"] = False, choose_method: bool = False,
           horizon: int | None = None, window: float | None = None,
           client: Any | None = None) -> Selection:
    """Choose past, future and order (module docstring) and identify the chosen model on all
    the data: :func:`plan`, then :func:`select_plan` (the other keywords are its own)."""
    p = plan(groups, pasts=pasts, futures=futures, orders=orders, validation=validation)
    return select_plan(p, method=method, options=options, workers=workers, progress=progress,
                       keep_models=keep_models, choose_focus=choose_focus,
                       choose_feedthrough=choose_feedthrough, choose_method=choose_method,
                       horizon=horizon, window=window, client=client)


def select_plan(p: Plan, *, method: Method, options: Options, workers: int = 1,
                progress: Callable[[int, int], None] | None = None, keep_models: bool = False,
                choose_focus: bool = False,
                choose_feedthrough: bool | Literal["open-loop"] = False,
                choose_method: bool = False,
                horizon: int | None = None, window: float | None = None,
                client: Any | None = None, feedback: FeedbackTest | None = None) -> Selection:
    """The selection on the data and grid of ``p``: :func:`sysid.sweep.sweep`, then
    :func:`finish`. With ``choose_focus`` the grid runs for both focus choices and
    :func:`pick_focus` decides; with ``choose_feedthrough`` (open-loop data only: module
    docstring) once more with a direct term, kept when it scores better (``"open-loop"``:
    only when :func:`sysid.feedback.feedback_test` finds no feedback). A focus or direct term
    chosen on data with feedback is biased by it: a warning says so
    (:func:`sysid.variants.biased_choices`); ``Selection.feedback`` is the test. With
    ``choose_method`` the method of :data:`sysid.variants.ALTERNATIVE` (PARSIM-K for IEM) is
    identified at the chosen horizons, with the focus and direct term chosen, over the grid's
    orders, and :func:`sysid.variants.pick_method` decides.
    ``progress(done, total)`` counts models over every run (``total`` is
    ``p.n_models * n_runs(...)``, more once the grid grows). ``horizon`` (k-step prediction)
    or ``window`` (simulation windows, s) replace the score's default (simulation over
    ``p.window_s``); ``client`` (Dask) runs the sweeps on a cluster; ``feedback``: the
    feedback test of ``p.ident`` when the caller has run it (not run again). Raises
    :class:`NoStableModel` when no model of the grid is stable."""
    quiet = without_input_warning() if choose_method and method.name in ALTERNATIVE \
        else contextlib.nullcontext()  # PARSIM-K is tried: IEM need not advise it
    with quiet:
        loop = None if not (choose_focus or choose_feedthrough) else \
            feedback if feedback is not None else feedback_test(p.ident)
        if loop is not None and feedback is None:
            log.info("selection: %s", loop.describe())
        skipped_d = ""
        if choose_feedthrough == "open-loop":  # a direct term only where no feedback was found
            choose_feedthrough = loop is not None and loop.feedback is False
            if loop is not None and loop.feedback and not getattr(options, "feedthrough", True):
                skipped_d = ("direct term not tried: the data read as closed loop "
                             f"({loop.describe()}), where a direct term also fits the "
                             "controller's instantaneous "
                             "response; estimate one anyway with --feedthrough "
                             "(feedthrough=True)")
        variants = ([dataclasses.replace(options, focus=f) for f in focus_order(options.focus)]
                    if choose_focus else [options])
        # the method choice's sweep (one pair of horizons over the orders) counted from the start
        alt_models = len(p.grid["orders"]) if choose_method and method.name in ALTERNATIVE else 0
        count = {"done": 0, "total": alt_models + p.n_models * n_runs(
            options, choose_focus=choose_focus, choose_feedthrough=choose_feedthrough)}

        def run(q: Plan, opts: Options, *, finishing: bool = True, keep: bool = False,
                meth: Method = method) -> tuple[SweepResult, Selection | None]:
            """One run of the grid of ``q`` with ``meth``: sweep, then finish; progress counts
            on."""
            start = count["done"]
            report = None if progress is None else (
                lambda done, _n: progress(start + done, count["total"]))
            score_window = None if horizon is not None else q.window_s if window is None else window
            result = sweep(q.ident, **q.grid, method=meth, options=opts, validation=q.val,
                           horizon=horizon, window=score_window, workers=workers, progress=report,
                           keep_models=keep_models or keep, client=client)
            count["done"] = start + q.n_models
            if not finishing:
                return result, None
            try:
                return result, finish(q, result, method=meth, options=opts)
            except DataError as exc:
                log.info("selection: focus %s, direct term %s: %s", opts.focus,
                         getattr(opts, "feedthrough", "-"), exc)
                return result, None

        def again(q: Plan, swept: dict[str, list[int]], sel: Selection) -> Selection | None:
            """``swept`` with the focus and direct term ``sel`` chose, chosen among its rows and
            those of ``sel`` on ``q`` (:func:`sysid.growth.follow_edges`)."""
            prov = sel.model.provenance
            opts = dataclasses.replace(options, focus=prov.get("focus", options.focus))
            if hasattr(opts, "feedthrough"):
                opts = dataclasses.replace(opts, feedthrough=bool(prov.get("feedthrough", False)))
            part = dataclasses.replace(q, grid=swept, window_s=sel.result.window or q.window_s)
            count["total"] += part.n_models
            result, _ = run(part, opts, finishing=False, keep=True)
            seen = {(r.past, r.future, r.order) for r in sel.result.rows}
            rows = [*sel.result.rows, *(r for r in result.rows
                                        if (r.past, r.future, r.order) not in seen)]
            merged = dataclasses.replace(sel.result, rows=tuple(
                sorted(rows, key=lambda r: (r.past, r.future, r.order))))
            try:
                return finish(q, merged, method=method, options=opts)
            except DataError:
                return None

        runs = [run(p, opts) for opts in variants]
        selections = [sel for _, sel in runs if sel is not None]
        if not selections:
            error = _no_stable(p, [result for result, _ in runs], either_focus=choose_focus)
            if not (choose_method and method.name in ALTERNATIVE):
                raise error
            alt = get_method(ALTERNATIVE[method.name])  # the whole grid with the other method
            log.info("selection: %s; trying %s", error, alt.name)
            try:
                sel = select_plan(p, method=alt, options=alt.options(
                    focus=options.focus, feedthrough=getattr(options, "feedthrough", False),
                    stability=options.stability), workers=workers, progress=progress,
                    keep_models=keep_models, choose_focus=choose_focus,
                    choose_feedthrough=choose_feedthrough, horizon=horizon, window=window,
                    client=client, feedback=loop)
            except NoStableModel:
                raise error from None
            return dataclasses.replace(sel, feedthrough_note=skipped_d or sel.feedthrough_note,
                                       method_note=f"method {alt.name}: {method.name}: "
                                                        f"{error}; {alt.name} on the same grid "
                                                        "chose the model")
        chosen = pick_focus(selections) if choose_focus else selections[0]
        if tries_feedthrough(options, choose_feedthrough):
            swept_d, with_d = run(p, dataclasses.replace(
                options, focus=chosen.model.provenance.get("focus", options.focus),
                feedthrough=True))
            none = None if with_d is not None else _no_stable(p, [swept_d], either_focus=False)
            chosen = pick_feedthrough(chosen, with_d) if with_d is not None else \
                dataclasses.replace(chosen, feedthrough_note=f"direct term tried, none kept: "
                                    f"{none}")  # it was silent (a static gain lost its D)
        chosen = follow_edges(p, chosen, room=p.room or max_blocks(p.ident), run=again)
        if choose_method and method.name in ALTERNATIVE:
            alt = get_method(ALTERNATIVE[method.name])
            prov = chosen.model.provenance
            alt_opts = alt.options(focus=prov.get("focus", options.focus),
                                   feedthrough=bool(prov.get("feedthrough", False)),
                                   stability=options.stability)
            orders = sorted({r.order for r in chosen.result.rows})
            q = dataclasses.replace(p, grid={"pasts": [chosen.best.past],
                                             "futures": [chosen.best.future], "orders": orders})
            count["total"] += q.n_models - alt_models
            other, _ = run(q, alt_opts, finishing=False, meth=alt)
            chosen = pick_method(chosen, other, name=alt.name, refit=lambda row, warnings: (
                final_model(q, row, warnings, method=alt, options=alt_opts)))
        # outliers and drift in every record the selection used (held-out parts included)
        quirks = data_warnings([*p.everything, *(p.val if p.given_validation else [])])
        if skipped_d:
            log.info("selection: %s", skipped_d)
            chosen = dataclasses.replace(chosen, feedthrough_note=skipped_d)
        return dataclasses.replace(chosen, feedback=loop, warnings=(
            *quirks, *chosen.warnings, *biased_choices(chosen, loop, focus_chosen=choose_focus,
                                              feedthrough_chosen=tries_feedthrough(
                                                  options, choose_feedthrough))))
