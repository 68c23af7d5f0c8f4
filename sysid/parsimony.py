"""The parsimonious choice scaled to the score's own noise (one-standard-error rule).

**Block errors** (:func:`block_errors`). The held-out score of a model is the floored mean fit
:math:`S = \\frac1l \\sum_i \\max(F_i, 0)` (:attr:`sysid.sweep.SweepRow.score`), each fit
:math:`F_i = 100\\,(1 - \\sqrt{E_i})` with :math:`E_i = \\|y_i - \\hat y_i\\|^2 / \\|y_i - \\bar
y_i\\|^2` over all the held-out data. The squared errors are accounted in contiguous *blocks*
:math:`b = 1..B` (the score's simulation windows, each cut into pieces when there are fewer than
:data:`MIN_BLOCKS` windows; one record scored in one piece is cut the same way),
:math:`E_i = \\sum_b \\varepsilon_{bi}`, so every row of a sweep carries a (B, l) array and the
score is a smooth function of block sums. Every model of a sweep is scored on the same blocks.

**Standard error of the score** (:func:`score_se`): the delete-one-block jackknife over the
blocks (blocks of a residual series as batches; Kuensch 1989),

.. math:: \\widehat{\\mathrm{se}}(S)^2 = \\frac{B-1}{B} \\sum_{b=1}^{B}
          \\big(S^{(-b)} - \\bar S^{(\\cdot)}\\big)^2, \\qquad
          S^{(-b)} = S\\Big(\\frac{E - \\varepsilon_{b}}{1 - \\delta_{b}}\\Big),

the score recomputed without block :math:`b`, the floor included (a channel floored in every
replicate adds nothing), its remaining errors scaled to the whole record by the share
:math:`\\delta_b` of the held-out samples the block holds (:func:`block_shares`; :math:`1/B`
for equal blocks), the spread in the denominator held fixed: every model is scored on the same
data, so the spread's own sampling error moves all scores alike and does not bear on their
ranking. Blocks of unequal length (records of different lengths, a longer last window,
merged pieces) then weigh what they hold; scaling the rest by :math:`B/(B-1)` took a
150-sample validation flight beside 2000 samples for a shortcoming of the model (SE 0.23 ->
2.9 points, order 3 for a true 4). Removing each block's share of the spread as well (a
ratio jackknife) measured the spread's own variation: on CrazyPAD's short hover segments SE
1.9 -> 6.1 points, and other choices there and on DaISy robot_arm and exchanger, 1-2 points
worse under the protocol.

**Rule** (:func:`tolerance`, :func:`parsimonious`): the one-standard-error rule (Breiman et
al. 1984; Hastie, Tibshirani and Friedman, *The Elements of Statistical Learning*, 7.10).
With :math:`a` the best-scoring row, keep the rows within one standard error of its score,

.. math:: S_a - S_r \\le \\tau = \\max\\big(\\widehat{\\mathrm{se}}(S_a),\\ \\tau_0\\big),

and take the smallest order among them (then the best score). The tolerance is the precision
with which the held-out data measure the best score: where the score is precise a larger order
that is better by more than that is taken (a fixed 0.5-point tolerance stopped one order short
there, its truth 1.7 points better); where it is noisy the tolerance grows and the smaller
order is taken. :math:`\\tau_0` = :data:`FLOOR_POINTS` is a resolution floor: a few hundredths
of a point on a long record are no reason for more states. The SE of the *paired* difference
:math:`S_a - S_r` (every model is scored on the same blocks) would be smaller, but it is a test
of whether the difference is real on *this* held-out data, and consistent small advantages of
larger orders are real there without being better models of the plant: the per-window initial
state of a larger model follows more of the output noise, and the best row is the largest of up
to a thousand scores. Measured on 41 synthetic known systems, the paired rule chose orders 7-9
for true orders 4-5 with innovation noise (2-2.5 points worse on the noise-free truth), the
rule above did not. Rows without block errors (built by hand) fall back to the fixed
:data:`FIXED_TOL`.

The same margin decides the focus and the direct term (:func:`significantly_better`): the
alternative is taken when it scores better by more than one standard error of its score.

**Warning** (:func:`ranking_warning`): when :math:`\\widehat{\\mathrm{se}}(S_a) \\ge`
:data:`UNRESOLVED_POINTS` and models of several orders score within it, the held-out data
cannot rank models a few points apart, whatever the rule; when it is at least
:data:`IMPRECISE_POINTS`, the held-out score itself says little even if one order ranks
first; when even the best score is 0 % (no model simulates any held-out output better than
its mean: every channel floored), nothing was ranked and the order is the rule's default.
The selection says so (more or longer validation data is the remedy), unless fewer
than half the blocks, each far out among the jackknife replicates (:data:`DOMINANT_Z` robust
standard deviations), make at least half its variance (:func:`dominant_blocks`): then the data
are not too few but a few stretches of them are odd (outliers, a burst of disturbance), and the
warning names the blocks and the standard error without them. Discounting those blocks in the
rule itself (the steamgen-like record with 12 outliers of 15 standard deviations: SE 8.9 ->
0.02 points, order 3 -> 8 for a true 8) was measured and not adopted: on 10 clean synthetic
cases of ``bench select`` it changed the choice of case 25 (a lightly damped system with
innovation noise, one block 8 robust standard deviations out: order 6 -> 8), where that
block's disturbance is the score's real uncertainty. A standard error
of a point with one order clearly first (the demo flights: 1.1 points, order 12 alone within
it) is not flagged: the data rank the orders.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Collection, Sequence
from typing import Protocol

import numpy as np

from sysid.comparison import CompareResult
from sysid.validate import split_windows

__all__ = ["DOMINANT_Z", "FIXED_TOL", "FLOOR_POINTS", "GRID_OPTIONS", "IMPRECISE_POINTS", "LEAST",
           "LOW_SCORE_POINTS", "MAX_BLOCKS", "MIN_BLOCKS", "UNRESOLVED_POINTS", "binding_edges",
           "block_errors", "block_shares", "close_to_best", "dominant_blocks", "edge_warnings",
           "parsimonious", "ranking_warning", "rising_edges", "score_se", "scores",
           "significantly_better", "tolerance", "tolerance_basis"]

#: Fewest blocks the errors are accounted in: windows are cut into pieces below this count.
MIN_BLOCKS = 10
#: Most blocks kept per row (consecutive blocks are merged beyond): (B, l) floats per model.
MAX_BLOCKS = 100
#: Shortest piece a window is cut into, samples.
MIN_PIECE_SAMPLES = 10
#: Resolution floor of the tolerance, points of score.
FLOOR_POINTS = 0.1
#: Fixed tolerance (points) for rows that carry no block errors.
FIXED_TOL = 0.5
#: Warn when the best score's standard error is at least this many points and several orders
#: score within it: its 95 % interval is then +- 2 points or wider, the distance at which models
#: are told apart as different.
UNRESOLVED_POINTS = 1.0
#: ... and whatever the orders within it, when it is at least this many (+- 6 points at 95 %).
IMPRECISE_POINTS = 3.0
#: A best held-out score under this (percent) is warned of: the model explains under a fifth
#: of the held-out outputs' variance (fit 10 % = residual norm 0.9 of the outputs').
LOW_SCORE_POINTS = 10.0
#: A block whose jackknife replicate lies more than this many robust standard deviations from
#: the replicates' median dominates the spread (:func:`dominant_blocks`).
DOMINANT_Z = 5.0


class Scored(Protocol):
    """What the rule needs of a row (:class:`sysid.sweep.SweepRow`)."""

    past: int
    future: int
    order: int

    @property
    def score(self) -> float: ...  # pragma: no cover

    @property
    def errors(self) -> np.ndarray | None: ...  # pragma: no cover

    @property
    def shares(self) -> np.ndarray | None: ...  # pragma: no cover


def _pieces(length: int, count: int) -> list[tuple[int, int]]:
    """``count`` (fewer if short) contiguous near-equal pieces of ``range(length)``."""
    count = max(1, min(count, length // MIN_PIECE_SAMPLES))
    edges = np.linspace(0, length, count + 1).round().astype(int)
    return list(zip(edges[:-1].tolist(), edges[1:].tolist(), strict=True))


def _blocks(res: CompareResult) -> tuple[tuple[tuple[int, int, int], ...], ...]:
    """The blocks of ``res``, each a tuple of ``(record, start, stop)`` pieces: the score's
    windows (``res.window`` samples, split by :func:`sysid.validate.split_windows` as
    :func:`sysid.compare` splits them) or whole records, cut into pieces of at least
    :data:`MIN_PIECE_SAMPLES` samples when there are fewer than :data:`MIN_BLOCKS`; beyond
    :data:`MAX_BLOCKS`, consecutive pieces share a block. They depend on the records' lengths
    and the window only, the same for every model of a sweep: worked out once
    (:func:`_block_layout`)."""
    return _block_layout(tuple(y.shape[0] for y in res.y_measured), res.window)


@functools.lru_cache(maxsize=32)
def _block_layout(lengths: tuple[int, ...], window: int | None
                  ) -> tuple[tuple[tuple[int, int, int], ...], ...]:
    """:func:`_blocks` of records of ``lengths`` samples scored over ``window``."""
    windows = []
    for e, n in enumerate(lengths):
        windows += [(e, sl.start, sl.stop) for sl in split_windows(n, window or n)]
    per = math.ceil(MIN_BLOCKS / len(windows))
    pieces = [(e, a + a2, a + b2) for e, a, b in windows for a2, b2 in _pieces(b - a, per)]
    if len(pieces) <= MAX_BLOCKS:
        return tuple((piece,) for piece in pieces)
    return tuple(tuple(pieces[i] for i in g)
                 for g in np.array_split(np.arange(len(pieces)), MAX_BLOCKS))


def block_errors(res: CompareResult) -> np.ndarray:
    """Squared errors of ``res`` per block and channel, (B, l), each divided by the channel's
    squared spread over all the data: ``100 * (1 - sqrt(errors.sum(0)))`` is ``res.fit``
    (module docstring; blocks: :func:`_blocks`); NaN for a constant channel."""
    y_all = np.vstack(res.y_measured)
    spread = np.sum((y_all - y_all.mean(axis=0)) ** 2, axis=0)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        sse = np.array([sum(np.sum((res.y_measured[e][a:b] - res.y_model[e][a:b]) ** 2, axis=0)
                            for e, a, b in block) for block in _blocks(res)])
        sse[~np.isfinite(sse)] = np.inf
        out = sse / spread
    out[:, spread == 0] = np.nan
    return out


def block_shares(res: CompareResult) -> np.ndarray:
    """Each block's share of the held-out samples, (B,), summing to 1: how much of the data
    leaves with the block (:func:`score_se`)."""
    counts = np.array([sum(b - a for _, a, b in block) for block in _blocks(res)], dtype=float)
    return counts / counts.sum()


def scores(errors: np.ndarray) -> np.ndarray:
    """Floored mean fit (points) of block-summed errors ``(..., l)``: ``mean max(F, 0)``."""
    with np.errstate(invalid="ignore"):
        fit = 100.0 * (1.0 - np.sqrt(errors))
    return np.mean(np.clip(fit, 0.0, None), axis=-1)


def score_se(row: Scored) -> float:
    """Jackknife standard error of ``row.score`` over its blocks (module docstring), points;
    NaN without block errors or with fewer than two blocks."""
    e = row.errors
    if e is None or e.shape[0] < 2 or not np.isfinite(row.score):
        return float("nan")
    n_blocks = e.shape[0]
    rep = _replicates(row)
    return float(np.sqrt((n_blocks - 1) / n_blocks * np.sum((rep - rep.mean()) ** 2)))


def tolerance(best: Scored, *, tol: float | None = None) -> float:
    """How much worse than ``best`` a row may score and still count as good as it, points:
    ``tol`` when given (a fixed tolerance), else ``max(se(best.score), FLOOR_POINTS)``, or
    :data:`FIXED_TOL` when ``best`` carries no block errors."""
    if tol is not None:
        return float(tol)
    se = score_se(best)
    return max(se, FLOOR_POINTS) if np.isfinite(se) else FIXED_TOL


def tolerance_basis(best: Scored) -> str:
    """What :func:`tolerance` rests on for ``best``, for a report: ``"one standard error"``,
    or the fixed fallback and why."""
    if np.isfinite(score_se(best)):
        return "one standard error"
    return (f"fixed: {'no block errors' if best.errors is None else 'one held-out block'}, "
            "no standard error")


def close_to_best(ranked: Sequence[Scored], *, tol: float | None = None) -> list[Scored]:
    """The rows of ``ranked`` (best score first, not empty) within :func:`tolerance` of the
    first."""
    limit = ranked[0].score - tolerance(ranked[0], tol=tol)
    return [r for r in ranked if r.score >= limit]


def parsimonious(ranked: Sequence[Scored], *, tol: float | None = None) -> Scored:
    """The smallest-order row of :func:`close_to_best`, then the best score."""
    return min(close_to_best(ranked, tol=tol), key=lambda r: (r.order, -r.score))


def significantly_better(candidate: Scored, incumbent: Scored, *, tol: float | None = None
                         ) -> tuple[bool, float]:
    """Whether ``candidate`` scores better than ``incumbent`` by more than
    :func:`tolerance` of ``candidate`` (one standard error of its score), and that margin."""
    margin = tolerance(candidate, tol=tol)
    return bool(candidate.score - incumbent.score > margin), margin


def _replicates(row: Scored) -> np.ndarray:
    """The jackknife replicates :math:`S^{(-b)}` of ``row.score`` (B,) (module docstring)."""
    e = row.errors
    n_blocks = e.shape[0]
    shares = getattr(row, "shares", None)  # hand-made rows: equal blocks
    rest = 1.0 - (np.full(n_blocks, 1.0 / n_blocks) if shares is None else shares)[:, None]
    total = e.sum(axis=0)  # a diverged channel (inf) stays diverged without any one block
    with np.errstate(invalid="ignore", divide="ignore"):
        left = np.where(rest > 1e-12, (total - e) / rest, total)
        return scores(np.where(np.isfinite(total), left, np.inf))


def dominant_blocks(row: Scored) -> tuple[np.ndarray, float] | None:
    """The held-out blocks that make most of the spread of ``row.score``, and the standard
    error without them (points), or None.

    A block dominates when its replicate :math:`S^{(-b)}` lies more than
    :data:`DOMINANT_Z` robust standard deviations (1.4826 times the median absolute
    deviation of the replicates) from their median; they must be fewer than half the blocks
    (at least :data:`MIN_BLOCKS`) and hold at least half the jackknife variance. One
    corrupted sample or a burst of disturbance in a block does that: its error is the same
    for every model, so it widens the standard error without telling the models apart.

    Parameters
    ----------
    row : a scored row with block errors (B, l).

    Returns
    -------
    (indices (k,) of the blocks in held-out order, standard error of the other blocks'
    replicates, points) or None.
    """
    e = row.errors
    if e is None or e.shape[0] < MIN_BLOCKS or not np.isfinite(row.score):
        return None
    rep = _replicates(row)
    if not np.all(np.isfinite(rep)):
        return None
    n_blocks = rep.size
    med = np.median(rep)
    scale = 1.4826 * np.median(np.abs(rep - med))
    if scale <= 0:
        return None
    far = np.flatnonzero(np.abs(rep - med) > DOMINANT_Z * scale)
    dev2 = (rep - rep.mean()) ** 2
    if not far.size or 2 * far.size >= n_blocks or dev2[far].sum() < 0.5 * dev2.sum():
        return None
    rest = np.delete(rep, far)
    return far, float(np.sqrt((n_blocks - 1) / rest.size * np.sum((rest - rest.mean()) ** 2)))


def ranking_warning(ranked: Sequence[Scored], *, n_samples: int,
                    validation_given: bool = False) -> str | None:
    """A warning when the held-out data cannot rank the models or measure the score: the
    standard error of the best score (:func:`score_se`) is at least
    :data:`UNRESOLVED_POINTS` and models of several orders score within it (scores two
    points apart, the width of its 95 % interval, cannot be told apart), or it is at least
    :data:`IMPRECISE_POINTS` (the held-out score itself says little of the model, whichever
    order wins), or there are fewer than :data:`MIN_BLOCKS` blocks to measure it on (under
    about 100 held-out samples). When a few blocks make most of that spread
    (:func:`dominant_blocks`, and the standard error without them is under
    :data:`UNRESOLVED_POINTS`) the warning names them and where to look (outliers or a
    disturbance there) instead of only asking for more data.
    ``ranked``: the candidates, best score first; ``n_samples``: held-out samples;
    ``validation_given``: the held-out samples are validation flights the caller gave
    (:attr:`sysid.holdout.Plan.given_validation`), so the remedy asks for longer ones or
    more of them rather than for validation flights as if none had been given. None when
    the score is precise enough, or ranks one order clearly above the rest. When even the best
    score is 0 % (no model simulates any held-out output better than its mean), the warning
    says that the choice was the rule's default and not a measurement; under
    :data:`LOW_SCORE_POINTS`, that the inputs explain little of the outputs."""
    se = score_se(ranked[0])
    remedy = ("the validation flights given are too short or too few: give longer ones or "
              "more of them" if validation_given else
              "give longer or more validation flights (sysid sweep --validate)")
    if ranked[0].score <= 0.0:  # every channel of every model floored: nothing was ranked
        return (f"no model of the grid simulates any of the {n_samples} held-out samples' "
                f"outputs better than their mean (every score 0 %): the held-out data cannot "
                f"rank the models and the smallest order was taken by default, not by "
                f"measurement; the records may be too short for their channels or the held-out "
                f"part unlike the rest: give horizons and an order (--past/--future/--order) "
                f"and check the fit on other data, or {remedy}")
    if ranked[0].score < LOW_SCORE_POINTS:  # a choice, but of models that explain ~nothing
        return (f"the best model simulates the {n_samples} held-out samples' outputs hardly "
                f"better than their mean (score {ranked[0].score:.1f} %, {LOW_SCORE_POINTS:g} % "
                f"or more is a model worth checking): the inputs explain little of the outputs "
                f"at these horizons and orders (outputs the inputs do not drive, a static gain "
                f"with no dynamics, or too few samples); check the channels, and the fit on "
                f"other data, or {remedy}")
    elsewhere = "validate on other flights" + ("" if validation_given else
                                                 " (sysid sweep --validate)")
    if np.isfinite(se) and se >= UNRESOLVED_POINTS:
        few = dominant_blocks(ranked[0])
        if few is not None and few[1] < UNRESOLVED_POINTS:  # they do make the spread
            blocks, rest = few
            which = (f"block {blocks[0] + 1} makes" if blocks.size == 1 else
                     f"blocks {', '.join(str(b + 1) for b in blocks)} make")
            remedy = (f"most of that spread comes from {blocks.size} of its "
                      f"{ranked[0].errors.shape[0]} held-out blocks ({which} it, in held-out "
                      f"order; +- {rest:.2f} points without them): look there for outliers "
                      f"(sysid.quirks.outlier_warnings; sysid.preprocess.despike replaces "
                      f"them) or a disturbance, or {elsewhere}")
        orders = sorted({r.order for r in close_to_best(ranked)})
        if len(orders) > 1:
            return (f"the {n_samples} held-out samples cannot rank the models: they measure "
                    f"the score only to +- {se:.1f} points (one standard error of the best, "
                    f"{ranked[0].score:.1f} %), and orders {orders[0]} to {orders[-1]} score "
                    f"within that of the best; {remedy}")
        if se >= IMPRECISE_POINTS:
            return (f"the {n_samples} held-out samples measure the score only to +- "
                    f"{se:.1f} points (one standard error of the best, "
                    f"{ranked[0].score:.1f} %): order {orders[0]} ranks first, but the score "
                    f"says little of how the model will validate; {remedy}")
    blocks = ranked[0].errors
    if blocks is not None and blocks.shape[0] < MIN_BLOCKS:
        count = blocks.shape[0]
        return (f"the {n_samples} held-out samples are too few to measure reliably how "
                f"precise the score is: its standard error comes from how the score varies "
                f"between stretches of at least {MIN_PIECE_SAMPLES} held-out samples, and "
                f"they make {count} such stretch{'' if count == 1 else 'es'} where "
                f"{MIN_BLOCKS} are needed (about {MIN_BLOCKS * MIN_PIECE_SAMPLES} held-out "
                f"samples); the choice used {tolerance(ranked[0]):.2g} points as its "
                f"tolerance; {remedy}")
    return None


def binding_edges(best: Scored, ranked: Sequence[Scored], grid: dict[str, list[int]], *,
                  tol: float | None = None) -> list[tuple[str, str]]:
    """The edges of the grid the scores say may be binding, as ``(parameter, side)`` with
    parameter ``"past"``, ``"future"`` or ``"order"`` and side ``"above"`` or ``"below"``.

    The choice sits at the largest (smallest) past, future or order tried, and no stable row
    with another value of that parameter scores as well as the best one (within one standard
    error of its score, :func:`close_to_best`, or a fixed ``tol`` points): the score is still
    rising towards the edge. When rows inside the grid score as well (a flat top: the held-out
    score cannot tell them apart), the edge is not binding. ``ranked``: the stable rows, best
    score first, ``best`` among them. A smallest value that is the least possible
    (:data:`LEAST`) has nothing below it and is never binding."""
    close = close_to_best(ranked, tol=tol)
    out = []
    for name, value, side in _edges(best, grid):
        if any(getattr(r, name) != value for r in close):
            continue
        out.append((name, side))
    return out


#: The least value of each parameter (past 1, future 2, order 1): a choice there has no
#: smaller one to try.
LEAST = {"past": 1, "future": 2, "order": 1}
#: The option of ``sysid sweep`` that gives each parameter's values.
GRID_OPTIONS = {"past": "--pasts", "future": "--futures", "order": "--orders"}


def _edges(best: Scored, grid: dict[str, list[int]]) -> list[tuple[str, int, str]]:
    """``(parameter, value, side)`` for each parameter whose chosen value in ``best`` is the
    largest (``"above"``) or smallest (``"below"``, unless :data:`LEAST`) of at least two
    values in ``grid``."""
    out = []
    for name, value in (("past", best.past), ("future", best.future), ("order", best.order)):
        values = grid[f"{name}s"]
        if len(values) < 2:
            continue
        if value == max(values):
            out.append((name, value, "above"))
        elif value == min(values) and value > LEAST[name]:
            out.append((name, value, "below"))
    return out


def rising_edges(best: Scored, ranked: Sequence[Scored], grid: dict[str, list[int]],
                 given: Collection[str]) -> list[tuple[str, str, Scored]]:
    """The edges of the values the caller gave (``given`` holds ``"pasts"``, ``"futures"``,
    ``"orders"``) where the choice sits and scores at least :data:`FLOOR_POINTS` (the
    resolution floor) higher than the next value inside the grid, the other two parameters as
    chosen: ``(parameter, side, that inner row)``.

    Within one standard error such an edge is not binding (:func:`binding_edges`: the
    held-out score cannot tell the values apart) and a default grid is not grown past it;
    but a grid the caller gave is theirs to extend, and a score still rising at its edge is
    what they need to know to do it. ``ranked``: the stable rows, ``best`` among them."""
    out = []
    for name, _value, side in _edges(best, grid):
        if f"{name}s" not in given:
            continue
        values = sorted(grid[f"{name}s"])
        inner = values[-2] if side == "above" else values[1]
        others = [n for n in ("past", "future", "order") if n != name]
        row = next((r for r in ranked if getattr(r, name) == inner
                    and all(getattr(r, n) == getattr(best, n) for n in others)), None)
        if row is not None and best.score - row.score >= FLOOR_POINTS:
            out.append((name, side, row))
    return out


def edge_warnings(best: Scored, ranked: Sequence[Scored], grid: dict[str, list[int]], *,
                  capped: bool, tol: float | None = None, n_outputs: int | None = None,
                  given: Collection[str] = ()) -> list[str]:
    """A warning for each of :func:`binding_edges`; ``capped``: the data cut the horizons
    short of the default grid's range (:func:`sysid.auto.plan`); ``n_outputs``: says when an
    order is the most the largest future's rank allows, ``(f - 1) l``. ``given``: the
    parameters whose values the caller gave (``"pasts"``, ``"futures"``, ``"orders"``, never
    grown): their edges are also flagged while the score still rises towards them within one
    standard error (:func:`rising_edges`), and their warnings name the option to extend
    (:data:`GRID_OPTIONS`)."""
    binding = binding_edges(best, ranked, grid, tol=tol)
    rising = {(name, side): row for name, side, row in rising_edges(best, ranked, grid, given)}
    out = []
    for name, value, side in _edges(best, grid):
        if (name, side) not in binding and (name, side) not in rising:
            continue
        if side == "above":
            why = " (the data allow no longer horizons)" if capped and name != "order" else ""
            if name == "order" and n_outputs and value >= (grid["futures"][-1] - 1) * n_outputs:
                why = f" (the most a future of {grid['futures'][-1]} allows)"
            text, where = f"{name} {value} is the largest tried{why}", "beyond"
        else:
            text, where = f"{name} {value} is the smallest tried", "below"
        if (name, side) not in binding:
            row = rising[(name, side)]
            text += (f" and the score still rose towards it ({row.score:.1f} % at {name} "
                     f"{getattr(row, name)}, {best.score:.1f} % at {value}, less than the "
                     "tolerance apart)")
        text += f": the best may lie {where}"
        if f"{name}s" in given:
            text += f"; extend {GRID_OPTIONS[name]} {where} {value}"
        out.append(text)
    return out
