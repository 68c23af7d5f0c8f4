"""The data and grid of a no-knobs selection: the held-out split and the default grid.

**Held-out rule** (:func:`holdout`). With experiments from several sessions, the experiments
of the *last* session validate and those of the others identify. With one session, the first
70 % of each of its experiments identifies and the last 30 % validates.

**Default grid** (:func:`default_grid`), scaled to the data's memory in samples, not to the
sample time: the lag of the best VARX model by AICc (:func:`sysid.memory.predictor_memory`,
as MATLAB's ``n4sid`` chooses its horizons) is how many past samples the one-step predictor
needs. Pasts from a third of it to three times it, futures from a sixth of it to one and a
half times it, about evenly spaced on a log scale (the quadrotor flights of ``groundstation
demo --speed inf`` have a memory of 6 samples at 50 Hz: pasts 2 to 18, futures 2 to 9, where
the thesis used 60 and 17); both capped so that the identification data have at least
three Hankel columns per row of the largest pair. Orders 2 to 12, capped by the rank the
horizons allow. On a record so short that those caps leave the largest future unable to hold
the order of the memory (a VARX model of lag ``L`` has order ``L l``: :func:`memory_future`),
that future is added with fewer Hankel columns per row, down to one (a fat Hankel matrix, as
``n4sid`` uses on short records; :data:`MIN_COLUMNS_PER_ROW`): 60 samples of a third-order
SISO system had futures of 2 and order 1 at most.

When the records are too short for the memory itself to be measured (the VARX lag search
stops at the longest lag they allow, and picks it: :attr:`sysid.memory.Memory.capped` below
:data:`sysid.memory.MAX_LAG`), the memory is only a lower bound; if the grid it sets then
reaches no order above ``max(2, l)`` (no more than a future of 2 holds), the largest future
the records hold at one Hankel column per row is added, up to the future of order 12
(:func:`short_record_future`), and the held-out score chooses. On 57 samples of 5-input,
2-output systems of order 3 to 5 (6-8 seeds each, noise 0.05 and 0.3) the grid was future 2,
order 2 only, and the chosen models fit the noise-free truth 62-67 % (mean); with the added
future 3, 89-99 % (80 and 120 samples: 65-67 % -> 89-99 %; 40 samples of second-order SISO
systems at 20 dB, 8 seeds: -80 -> 95 %). Grids that already reach higher orders are left as
they are: adding the future to every grid on a capped memory made some choices worse (80
samples, one input, noise 0.3: 87 -> 75 %). Identification data too short for past 2, future
2 at one column per row are refused: a 5-input, 2-output record of 38 samples holds out 11
and identifies on 27, where only past 1, future 2 (order 2 at most) fit; that model fit true
order-3 and -4 systems 63-65 % (mean of 6 seeds; order 2: 99 %), against 92-99 % for past 1,
future 3, order 3 on all 38 samples of the order-3 ones, which the refusal's
--past/--future/--order give.

:func:`plan` makes the :class:`Plan` that :func:`sysid.auto.select_plan` sweeps;
:func:`unexcited_warning` says when its held-out inputs do not move (nothing to rank by).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData, as_flights
from sysid.errors import DataError, DimensionError
from sysid.memory import MAX_LAG as MEMORY_MAX_LAG
from sysid.memory import predictor_memory
from sysid.validate import min_fit_samples, simulation_window

__all__ = ["COLUMNS_PER_ROW", "FUTURE_X", "GIVE_HORIZONS", "HOLDOUT_FRACTION",
           "MIN_COLUMNS_PER_ROW", "ORDERS", "PAST_X", "QUIET_INPUT", "SCORE_WINDOW_X",
           "VALIDATE_WITH", "Plan", "default_grid", "holdout", "max_blocks", "memory_future",
           "plan", "short_record_future", "unexcited_warning"]

log = logging.getLogger(__name__)

#: Share of each experiment kept for validation when only one session is given.
HOLDOUT_FRACTION = 0.3
#: Hankel columns per row of the largest pair the default grid leaves at least.
COLUMNS_PER_ROW = 3.0
#: Fewest Hankel columns per row the default grid takes on a record too short for three: only
#: for the one future that holds the memory's order (:func:`memory_future`), or for past 2,
#: future 2; the fewest a sweep accepts (:func:`sysid.cli_sweep.check_sweep_horizons`).
MIN_COLUMNS_PER_ROW = 1.0
#: Pasts and futures of the default grid, as multiples of the predictor's memory (samples).
PAST_X = (1 / 3, 3.0)
FUTURE_X = (1 / 6, 1.5)
ORDERS = (2, 12)
#: Simulation windows of the score, in multiples of the data's memory (samples; at least 20
#: samples and 10 output values per initial-state parameter, at most the shortest validation
#: record: :func:`sysid.validate.simulation_window`).
SCORE_WINDOW_X = 12


def holdout(groups: Sequence[Sequence[IOData]], *, fraction: float = HOLDOUT_FRACTION
            ) -> tuple[list[IOData], list[IOData], str]:
    """``(identification, validation, rule)`` by the held-out rule (module docstring);
    ``groups`` holds the experiments of each session."""
    groups = [list(g) for g in groups if g]
    if len(groups) > 1:
        ident = [e for g in groups[:-1] for e in g]
        val = groups[-1]
        return ident, val, (f"identified on {len(ident)} experiment(s) of the first "
                            f"{len(groups) - 1} session(s), validated on the last session "
                            f"({len(val)} experiment(s))")
    ident, val = [], []
    for e in groups[0]:
        cut = round(e.n_samples * (1.0 - fraction))
        ident.append(_part(e, 0, cut))
        val.append(_part(e, cut, e.n_samples))
    return ident, val, (f"one session: the first {100 * (1 - fraction):.0f} % of each of its "
                        f"{len(ident)} experiment(s) identifies, the last "
                        f"{100 * fraction:.0f} % validates")


def _scorable(val: list[IOData], *, n_states: int, n_outputs: int) -> list[IOData]:
    """The held-out records long enough to score a model with its own initial state on
    (:func:`sysid.validate.min_fit_samples` for the grid's largest order); the others are
    left out with a warning. One short record capped every record's score window at its
    length: a 3-sample experiment beside a 3000-sample one made no knobs refuse the data, and
    one of 5 samples scored every model 100 % (degenerate-data review). All too short: kept,
    for the callers' refusal."""
    need = min_fit_samples(n_states=n_states, n_outputs=n_outputs)
    kept = [d for d in val if d.n_samples >= need]
    if kept and len(kept) < len(val):
        short = [d for d in val if d.n_samples < need]
        log.warning("%d held-out record(s) of %s sample(s) left out of the score: under the %d "
                    "samples a model's fit with its own initial state needs (%s)", len(short),
                    ", ".join(str(d.n_samples) for d in short[:5]), need,
                    ", ".join(d.source or "unnamed" for d in short[:3]))
    return kept or val


def _part(d: IOData, start: int, stop: int) -> IOData:
    return dataclasses.replace(d, u=d.u[start:stop], y=d.y[start:stop])


def _spread(low: int, high: int, count: int) -> list[int]:
    if high <= low:
        return [max(high, 1)]
    return sorted({round(v) for v in np.geomspace(low, high, count)})


def max_blocks(flights: Sequence[IOData], *, columns_per_row: float = COLUMNS_PER_ROW) -> int:
    """Largest ``past + future`` leaving ``columns_per_row`` Hankel columns per row."""
    c = flights[0].n_inputs + flights[0].n_outputs
    best = 0
    for b in range(2, max(d.n_samples for d in flights) + 1):  # columns fall, rows grow
        if sum(max(d.n_samples - b + 1, 0) for d in flights) < columns_per_row * b * c:
            break
        best = b
    return best


def memory_future(lag: int, n_outputs: int) -> int:
    """The shortest future whose rank ``(f - 1) l`` holds the order of the data's memory:
    a VARX model of lag ``L`` has a realization of order ``L l`` (observer form), here at
    most the grid's largest order, ``ORDERS[1]``."""
    return _future_for(min(lag * n_outputs, ORDERS[1]), n_outputs)


def _future_for(order: int, n_outputs: int) -> int:
    """The shortest future whose rank ``(f - 1) l`` holds ``order``."""
    return -(-order // n_outputs) + 1


def short_record_future(flights: Sequence[IOData], grid: dict[str, list[int]], *,
                        memory_capped: bool, max_lag: int) -> int | None:
    """The future a grid on records too short to measure their memory adds (module
    docstring), or None.

    Parameters
    ----------
    flights : the identification records, each ``u`` (N, m), ``y`` (N, l).
    grid : the default grid so far (samples; states).
    memory_capped : whether the memory's lag is the longest one tried
        (:attr:`sysid.memory.Memory.capped`) ...
    max_lag : ... and that longest lag (samples): below :data:`sysid.memory.MAX_LAG` the
        records cut the search short.

    Returns
    -------
    The largest future (samples) the records hold beside the grid's largest past at one
    Hankel column per row, at most the future of order ``ORDERS[1]``, when the memory was
    cut short, the grid reaches no order above ``max(ORDERS[0], l)`` and that future is
    longer than the grid's; else None.
    """
    ell = flights[0].n_outputs
    if not memory_capped or max_lag >= MEMORY_MAX_LAG or grid["orders"][-1] > max(ORDERS[0],
                                                                                  ell):
        return None
    fat = max_blocks(flights, columns_per_row=MIN_COLUMNS_PER_ROW)
    top = min(_future_for(ORDERS[1], ell), fat - grid["pasts"][-1])
    return top if top > grid["futures"][-1] else None


#: What the refusal of records too short for the default grid asks for, as ``identify``
#: spells it (``give=`` of :func:`default_grid`).
GIVE_HORIZONS = "horizons and an order (--past/--future/--order)"
#: How the same refusal asks for validation data of their own, which leave every sample
#: given to identification (``validate_with=``; ``sysid sweep`` names its ``--validate``).
VALIDATE_WITH = "another session to validate on (the last session given validates)"


def default_grid(flights: Sequence[IOData], *, groups: Sequence[Sequence[IOData]] | None = None,
                 give: str = GIVE_HORIZONS, validate_with: str = VALIDATE_WITH
                 ) -> dict[str, list[int]]:
    """Pasts, futures and orders for ``flights`` (module docstring), in samples.

    Records too short for past 2, future 2 are refused in one line (:class:`DataError`)
    that asks for ``give`` (the caller's options for horizons), longer records or fewer
    channels. ``groups``: the experiments of each session that :func:`holdout` split into
    ``flights`` (identification), so the refusal names the samples given and those the
    held-out part leaves, and asks for ``validate_with`` too; None when ``flights`` are all
    the samples given."""
    return _grid(flights, groups=groups, give=give, validate_with=validate_with)[0]


def _grid(flights: Sequence[IOData], *, groups: Sequence[Sequence[IOData]] | None = None,
          give: str = GIVE_HORIZONS, validate_with: str = VALIDATE_WITH
          ) -> tuple[dict[str, list[int]], bool, int, int]:
    """The default grid, whether the data cut it short of the memory's range, the memory,
    and the largest ``past + future`` the grid may grow to (three Hankel columns per row, or
    the largest pair of a grid that needed fewer). ``groups``, ``give`` and
    ``validate_with`` as :func:`default_grid`."""
    ell = flights[0].n_outputs
    room = max_blocks(flights)
    fat = max_blocks(flights, columns_per_row=MIN_COLUMNS_PER_ROW)
    if room < 4 <= fat:  # past 2, future 2 only with fewer columns per row
        room = 4
    if room < 4:
        need = round(4 * (flights[0].n_inputs + ell) * MIN_COLUMNS_PER_ROW + 3)
        raise DataError(_too_few(flights, groups=groups, need=need, give=give,
                                 validate_with=validate_with))
    memory = predictor_memory(flights)
    lag = max(memory.lag, 1)
    f_hi = max(2, min(round(FUTURE_X[1] * lag), room // 3))
    f_lo = max(2, min(round(FUTURE_X[0] * lag), f_hi))
    futures = _spread(f_lo, f_hi, 4)
    p_hi = max(1, min(round(PAST_X[1] * lag), room - futures[-1]))
    p_lo = max(1, min(round(PAST_X[0] * lag), p_hi))
    pasts = _spread(p_lo, p_hi, 6)
    capped = p_hi < round(PAST_X[1] * lag) or memory.capped  # short data, or the longest lag
    longer = min(memory_future(lag, ell), fat - pasts[-1])
    if longer > futures[-1]:  # a short record: the future the memory's order needs
        futures.append(longer)
        room = max(room, pasts[-1] + longer)
    grid = {"pasts": pasts, "futures": futures, "orders": _orders(futures[-1], ell)}
    extra = short_record_future(flights, grid, memory_capped=memory.capped,
                                max_lag=memory.max_lag)
    if extra is not None:  # the memory is a lower bound, the orders no more than f=2's
        futures.append(extra)
        grid["orders"] = _orders(extra, ell)
        room = max(room, pasts[-1] + extra)
    return grid, capped, lag, room


def _too_few(flights: Sequence[IOData], *, groups: Sequence[Sequence[IOData]] | None,
             need: int, give: str, validate_with: str) -> str:
    """The one-line refusal of identification records too short for past 2, future 2 (about
    ``need`` samples for the longest), naming what was given and what the held-out rule
    left of it when ``flights`` were split from ``groups``."""
    c = flights[0].n_inputs + flights[0].n_outputs
    n = max(d.n_samples for d in flights)
    remedy = f"give {give}, longer records or fewer channels"
    groups = [list(g) for g in groups or () if g]
    if not groups:
        return (f"{n} identification samples are too few to choose horizons for {c} channels "
                f"(need about {need}); {remedy}")
    if len(groups) > 1:
        first = "the first session" if len(groups) == 2 else f"the first {len(groups) - 1} sessions"
        return (f"the longest identification record ({first}; the last session validates) "
                f"has {n} samples: too few to choose horizons for {c} channels (need about "
                f"{need}); {remedy}")
    given = max(d.n_samples for d in groups[0])
    keep = 1.0 - HOLDOUT_FRACTION
    total = next(k for k in range(need, 10 * need + 10) if round(k * keep) >= need)
    what = (f"the {given} samples given leave" if len(groups[0]) == 1 else
            f"the longest of the {len(groups[0])} records, {given} samples, leaves")
    return (f"{what} {n} for identification after the held-out {100 * HOLDOUT_FRACTION:.0f} % "
            f"(validation): too few to choose horizons for {c} channels (need about {need} for "
            f"identification, so about {total} in all); {remedy}, or {validate_with}: then "
            "every sample given identifies")


def _orders(future: int, n_outputs: int) -> list[int]:
    """Orders 2 to 12, capped by the rank a largest future of ``future`` allows."""
    top = max(1, min((future - 1) * n_outputs, ORDERS[1]))
    return list(range(min(ORDERS[0], top), top + 1))


@dataclass(frozen=True, eq=False)
class Plan:
    """The data and grid of a selection: identification and validation experiments, the
    rule that split them, the grid (samples), the score's simulation window (s) and the
    data's memory (samples, :mod:`sysid.memory`) when it set the horizons."""

    everything: list[IOData]
    ident: list[IOData]
    val: list[IOData]
    rule: str
    grid: dict[str, list[int]]
    window_s: float
    capped: bool
    given_validation: bool
    memory: int | None = None
    fixed: tuple[str, ...] = ()  # "pasts", "futures", "orders" the caller gave: never grown
    scored_grid: dict[str, list[int]] | None = None  # the first grid, once the grid grew
    room: int | None = None  # the largest past + future the grid may grow to (default grid)

    @property
    def n_models(self) -> int:
        """Models of the grid: pasts x futures x orders."""
        return len(self.grid["pasts"]) * len(self.grid["futures"]) * len(self.grid["orders"])


def plan(groups: Sequence[Sequence[IOData]], *, pasts: Sequence[int] | None = None,
         futures: Sequence[int] | None = None, orders: Sequence[int] | None = None,
         validation: Sequence[IOData] | None = None, give: str = GIVE_HORIZONS,
         validate_with: str = VALIDATE_WITH) -> Plan:
    """Split the data (held-out rule, or ``validation``) and choose the grid; given
    ``pasts``/``futures``/``orders`` replace the default grid's (orders not given go as high as
    the largest future allows). Data whose magnitudes would overflow the identification's
    sums of squares are refused first, in one line (:func:`sysid.data.check_magnitudes`).
    Identification data too short for the default grid are refused naming the samples given
    and those the held-out part leaves, and asking for ``give`` and ``validate_with``
    (:func:`default_grid`)."""
    everything = list(as_flights([e for g in groups for e in g]))
    if validation:
        ident, val = everything, list(validation)
        shapes = {(d.n_inputs, d.n_outputs) for d in [*ident, *val]}
        if len(shapes) > 1:
            raise DimensionError(f"the validation records' channels differ from the "
                                 f"identification data's (inputs, outputs): {sorted(shapes)}")
        as_flights(val)
        rule = f"identified on all {len(ident)} experiment(s), validated on the given ones"
    else:
        ident, val, rule = holdout(groups)
    if pasts and futures:  # no default grid: only the memory, for the score's window
        auto, capped, memory, room = {}, False, max(predictor_memory(ident).lag, 1), None
    else:
        auto, capped, memory, room = _grid(ident, groups=None if validation else groups,
                                           give=give, validate_with=validate_with)
    grid = {"pasts": sorted(pasts) if pasts else auto["pasts"],
            "futures": sorted(futures) if futures else auto["futures"]}
    grid["orders"] = (sorted(orders) if orders else  # as many as the futures allow
                      _orders(grid["futures"][-1], ident[0].n_outputs))
    val = _scorable(val, n_states=grid["orders"][-1], n_outputs=ident[0].n_outputs)
    shortest = min(d.n_samples for d in val)
    capped = capped and not pasts
    return Plan(everything=everything, ident=ident, val=val, rule=rule, grid=grid,
                window_s=simulation_window(dt=ident[0].dt, n_samples=shortest,
                                          samples=SCORE_WINDOW_X * memory,
                                          n_states=grid["orders"][-1],
                                          n_outputs=ident[0].n_outputs), capped=capped,
                given_validation=bool(validation),
                memory=None if pasts and futures else memory,
                fixed=tuple(k for k, v in (("pasts", pasts), ("futures", futures),
                                           ("orders", orders)) if v), room=room)


#: Held-out inputs whose rms (about each record's mean) is under this share of the
#: identification inputs' do not move: the held-out score then measures free responses only.
QUIET_INPUT = 0.01


def _input_rms(flights: Sequence[IOData]) -> np.ndarray:
    """``(m,)`` rms of each input about each record's mean, over the records' samples."""
    sq = sum(((d.u - d.u.mean(axis=0)) ** 2).sum(axis=0) for d in flights)
    return np.sqrt(sq / max(1, sum(d.n_samples for d in flights)))


def unexcited_warning(p: Plan) -> str | None:
    """A warning when no input moves on the held-out data (every input's rms under
    :data:`QUIET_INPUT` of its rms on the identification data: a step experiment whose last
    third holds the input, a flight that hovers after its excitation): the scores then say
    how fast each model's free response dies out, not how it follows the inputs, so the
    ranking says nothing of the dynamics. None otherwise."""
    ident, val = _input_rms(p.ident), _input_rms(p.val)
    moving = ident > 0
    if not moving.any() or (val[moving] >= QUIET_INPUT * ident[moving]).any():
        return None
    j = int(np.argmax(np.where(moving, val / np.where(moving, ident, 1.0), -1.0)))
    name = p.ident[0].input_names[j]
    where = "the validation flights given" if p.given_validation else "the held-out part"
    return (f"the inputs hardly move on {where} ({name}: rms {val[j]:.3g} against "
            f"{ident[j]:.3g} on the identification data, the most of any input): its scores "
            "measure how fast each model's free response dies out, not how it follows the "
            "inputs, so the choice of horizons and order is not a measurement; validate on "
            "data with excitation (sysid sweep --validate FLIGHT) or give --past/--future/"
            "--order")
