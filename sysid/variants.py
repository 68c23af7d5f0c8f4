"""Choosing the focus and the direct term of a selection on the held-out scores.

**Focus** (:func:`pick_focus`): when the caller does not fix it, :func:`sysid.auto.select_plan`
runs the grid with both focus choices and the one whose chosen model scores best on the
held-out data wins: the method's default (IEM: prediction) unless the other is better by more
than one standard error of its score (:func:`sysid.parsimony.significantly_better`).

**Direct term** (:func:`pick_feedthrough`, for open-loop data): a method without one (IEM's
default) runs the grid once more with ``feedthrough=True`` (the chosen focus), kept only when
it scores better by more than one standard error. Off by default: on closed-loop data (every
flight) a direct term fitted on the logged inputs is biased by the feedback, and held-out data
from the same loop would reward the bias.
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING

from sysid.methods import Options
from sysid.parsimony import significantly_better, tolerance

if TYPE_CHECKING:  # sysid.auto imports this module
    from sysid.auto import Selection
    from sysid.feedback import FeedbackTest
    from sysid.model import StateSpaceModel
    from sysid.sweep import SweepResult, SweepRow

__all__ = ["ALTERNATIVE", "biased_choices", "focus_order", "n_runs", "pick_feedthrough",
           "pick_focus", "pick_method", "tries_feedthrough"]

#: The method a selection also tries at the chosen horizons (``choose_method``): PARSIM-K for
#: IEM. Both are consistent in closed loop; PARSIM-K enforces the causal (Toeplitz) structure
#: of the future's input terms that IEM's row regressions leave free (Qin, Lin & Ljung 2005),
#: which keeps its variance down when the future inputs are nearly predictable from the past
#: (low-passed or slowly held inputs).
ALTERNATIVE = {"iem": "parsim-k"}

log = logging.getLogger("sysid.auto")  # part of the selection's report


def focus_order(default: str) -> list[str]:
    """Both focus choices, the method's default first (it wins ties, :func:`pick_focus`)."""
    return [default, *(f for f in ("prediction", "simulation") if f != default)]


def pick_focus(selections: Sequence[Selection], *, tol: float | None = None) -> Selection:
    """The selection whose chosen model scores best on the held-out data; the first one (the
    method's default focus) unless another is better by more than one standard error of its
    score (at least 0.1 points: :func:`sysid.parsimony.significantly_better`; by more than
    ``tol`` points when given). The reason is in :attr:`Selection.focus_note`."""
    first = selections[0]
    best = max(selections, key=lambda s: s.best.score)
    better, margin = significantly_better(best.best, first.best, tol=tol)
    chosen = best if better else first
    scores = ", ".join(f"{s.model.provenance.get('focus')} {s.best.score:.1f}"
                       for s in selections)
    note = (f"focus {chosen.model.provenance.get('focus')}: best held-out score per focus "
            f"{scores} (the method's default unless another is better by more than "
            f"{_points(margin)}{'' if tol is not None else ', one standard error'})")
    log.info("selection: %s", note)
    return dataclasses.replace(chosen, focus_note=note, focus_scores={
        str(s.model.provenance.get("focus")): float(s.best.score) for s in selections})


def pick_method(first: Selection, other: SweepResult, *, name: str,
                refit: Callable[[SweepRow, list[str]], StateSpaceModel]) -> Selection:
    """The cross-method parsimony rule at ``first``'s horizons. ``other``: the sweep of the
    method ``name`` there (:data:`ALTERNATIVE`); its parsimonious best row competes with
    ``first``'s chosen one. Of the two, those whose held-out score is within the tolerance
    (one standard error of the best score, at least 0.1 points: ``first.tolerance``) of the
    best stable score of either method, the one of smaller order wins; ``first`` (the
    caller's method) on a tie. When ``other`` wins, ``refit(row, warnings)`` identifies it
    on all the data (:func:`sysid.refit.final_model`) and the selection keeps ``first``'s
    candidates, grid and warnings (the search for the horizons was ``first``'s). The reason
    is in :attr:`Selection.method_note`."""
    mine = str(first.model.provenance.get("method"))
    ranked = other.ranked(require_stable=True)
    if not ranked:
        failed = other.failures()
        why = (f"failed ({failed[0][0]})" if failed and sum(n for _, n in failed) ==
               len(other.rows) else "has no stable model")
        note = (f"method {mine}: {name} {why} at past {first.best.past}, future "
                f"{first.best.future}")
        log.info("selection: %s", note)
        return dataclasses.replace(first, method_note=note)
    row = other.best()
    tol = tolerance(first.result.ranked(require_stable=True)[0]) if first.tolerance is None \
        else first.tolerance  # finish() sets it: sysid.parsimony.tolerance of the best
    top = max(first.result.ranked(require_stable=True)[0].score, ranked[0].score)
    first_close, row_close = (r.score >= top - tol for r in (first.best, row))
    wins = row_close and (row.order < first.best.order or not first_close)
    note = (f"method {name if wins else mine}: at past {first.best.past}, future "
            f"{first.best.future} {mine} chose order {first.best.order} (held-out "
            f"{first.best.score:.1f}), {name} order {row.order} ({row.score:.1f}); the smaller "
            f"order within {tol:.2g} points of the best ({top:.1f}) wins, {mine} on a tie")
    log.info("selection: %s", note)
    if not wins:
        return dataclasses.replace(first, method_note=note)
    warnings = [w for w in first.warnings if not w.startswith("identified again on all")]
    model = refit(row, warnings)
    return dataclasses.replace(first, best=row, model=model, warnings=tuple(warnings),
                               method_note=note)


def n_runs(options: Options, *, choose_focus: bool, choose_feedthrough: bool = False) -> int:
    """How many times :func:`select_plan` runs the grid: once per focus it tries, and once
    more when it tries a direct term."""
    return ((len(focus_order(options.focus)) if choose_focus else 1)
            + int(tries_feedthrough(options, choose_feedthrough)))


def tries_feedthrough(options: Options, choose: bool) -> bool:
    """Whether a selection tries a direct term: asked for, and the method has none by
    default."""
    return choose and getattr(options, "feedthrough", True) is False


def _points(margin: float) -> str:
    """``"1 point"``, ``"0.99 points"``."""
    text = f"{margin:.2g}"
    return f"{text} point" if text == "1" else f"{text} points"


def pick_feedthrough(without: Selection, with_d: Selection, *, tol: float | None = None
                     ) -> Selection:
    """``with_d`` (a direct term) when its chosen model scores better on the held-out data
    than ``without``'s by more than one standard error of its score
    (:func:`sysid.parsimony.significantly_better`; by more than ``tol`` points when given),
    else ``without``; the reason in :attr:`Selection.feedthrough_note`."""
    better, margin = significantly_better(with_d.best, without.best, tol=tol)
    note = (f"direct term {'kept' if better else 'left out'}: best held-out score "
            f"{with_d.best.score:.1f} with, {without.best.score:.1f} without (kept only when "
            f"better by more than {_points(margin)}"
            f"{'' if tol is not None else ', one standard error'})")
    log.info("selection: %s", note)
    chosen = dataclasses.replace(with_d, focus_note=without.focus_note,
                                 focus_scores=without.focus_scores) if better else without
    return dataclasses.replace(chosen, feedthrough_note=note)


def biased_choices(chosen: Selection, loop: FeedbackTest | None, *, focus_chosen: bool,
                   feedthrough_chosen: bool) -> list[str]:
    """Warnings for what the selection chose by held-out score that feedback biases: the
    simulation focus (output error) and a direct term, when ``loop`` found feedback. Held-out
    data from the same loop reward the bias (a model of the loop, not of the plant: on
    closed-loop test systems the simulation focus fitted the true plant 4-7 points worse than
    the prediction focus at the same settings; :mod:`sysid.feedback`)."""
    if loop is None or not loop.feedback:
        return []
    prov = chosen.model.provenance
    out = []
    if focus_chosen and prov.get("focus") == "simulation":
        out.append(f"the simulation focus scored best, but the inputs depend on past outputs "
                   f"({loop.evidence}): output error is biased by feedback, which held-out data "
                   "from the same loop reward; for the plant's own dynamics (control design) "
                   "give --focus prediction")
    if feedthrough_chosen and prov.get("feedthrough"):
        out.append(f"a direct term scored best, but the inputs depend on past outputs "
                   f"({loop.evidence}): it is biased by feedback; for the plant's own dynamics "
                   "give --no-feedthrough")
    return out
