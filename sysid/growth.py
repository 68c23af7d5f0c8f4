"""Growing the default grid where the held-out score still rises at its edge.

The default grid (:func:`sysid.auto.default_grid`) spans the data's memory; a system with
more states or a longer memory than it allows chooses at the grid's edge, and the selection
flags it (:func:`sysid.parsimony.binding_edges`: no row inside the grid in that parameter
scores within one standard error of the best). A researcher would then widen the grid and
sweep again; :func:`grown_grid` does that step, for the parameters the caller did not fix:

* a binding largest past or future: two more values, :data:`STEPS` times the largest (1.4x,
  2x), within the data's room (``past + future`` at most the largest pair the identification
  data hold with enough Hankel columns, :func:`sysid.auto.max_blocks`, and at most
  :data:`ROOM_X` times the first grid's; a future at most a third of the room, as the
  default grid);
* a binding smallest past or future: half of it (at least 1 and 2);
* a binding largest order: orders up to ``max(top + 4, 1.5 top)``, within the rank the
  longest future swept allows (``(f - 1) l``) and :data:`MAX_ORDER`; a binding smallest order: 1.

:func:`sysid.auto.select_plan` sweeps the grown grid again with the chosen focus and direct
term, at most :data:`MAX_ROUNDS` times; the edge warnings of the last round remain. On the
demo flights (six outputs, memory 6 samples) the default grid ends at future 9 and order 12,
where the score was still rising.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Collection, Sequence
from typing import TYPE_CHECKING

from sysid.parsimony import binding_edges

if TYPE_CHECKING:  # the selection's types; sysid.auto imports this module
    from sysid.auto import Plan, Selection

__all__ = ["MAX_ORDER", "MAX_ROUNDS", "ROOM_X", "STEPS", "describe", "follow_edges", "grown_grid"]

#: Sweeps of a grown grid at most, after the first.
MAX_ROUNDS = 2
#: A binding largest past or future gains these multiples of itself.
STEPS = (1.4, 2.0)
#: Orders never grow beyond this (``sysid identify --order`` allows up to 40).
MAX_ORDER = 40
#: The largest ``past + future`` never grows beyond this many times the first grid's, so the
#: Hankel matrix at most doubles its rows (its Gram matrix, the cost, at most quadruples).
ROOM_X = 2


def _beyond(values: list[int], *, side: str, limit: int, floor: int) -> list[int]:
    """New values past the edge ``side`` of ``values``, within ``[floor, limit]``."""
    if side == "above":
        top = values[-1]
        new = [round(top * s) for s in STEPS]
        return sorted({v for v in new if top < v <= limit})
    low = max(floor, values[0] // 2)
    return [low] if low < values[0] else []


def grown_grid(grid: dict[str, list[int]], edges: Sequence[tuple[str, str]], *, room: int,
               n_outputs: int, fixed: Collection[str] = (), future: int | None = None
               ) -> dict[str, list[int]] | None:
    """``grid`` grown past its binding ``edges`` (``(parameter, side)``, module docstring), or
    None when nothing can grow: the edges are fixed by the caller (``fixed`` holds
    ``"pasts"``, ``"futures"`` or ``"orders"``), the data hold no longer horizons (``room``:
    the largest ``past + future``), or larger orders need a longer future than will be swept
    (``future``: the chosen one, which the new futures join; default the grid's largest)."""
    new = {k: sorted(v) for k, v in grid.items()}
    sides = {name: side for name, side in edges if f"{name}s" not in fixed}
    reach = new["futures"][-1] if future is None else future  # the longest future swept
    if "future" in sides:
        more = _beyond(new["futures"], side=sides["future"], floor=2,
                       limit=min(room // 3, room - new["pasts"][-1]))
        new["futures"] = sorted({*new["futures"], *more})
        reach = max([reach, *more])
    if "past" in sides:
        more = _beyond(new["pasts"], side=sides["past"], floor=1,
                       limit=room - new["futures"][-1])
        new["pasts"] = sorted({*new["pasts"], *more})
    if "order" in sides:
        orders = new["orders"]
        if sides["order"] == "above":
            top = orders[-1]
            cap = min((reach - 1) * n_outputs, MAX_ORDER)
            grown = min(max(top + 4, round(1.5 * top)), cap)
            new["orders"] = sorted({*orders, *range(top + 1, grown + 1)})
        elif orders[0] > 1:
            new["orders"] = [1, *orders]
    return None if new == {k: sorted(v) for k, v in grid.items()} else new


def describe(before: dict[str, list[int]], after: dict[str, list[int]]) -> str:
    """What grew, for the selection's rule: ``"futures to 18, orders to 18"``."""
    parts = []
    for key in ("pasts", "futures", "orders"):
        b, a = before[key], after[key]
        if a[-1] > b[-1]:
            parts.append(f"{key} to {a[-1]}")
        if a[0] < b[0]:
            parts.append(f"{key} down to {a[0]}")
    return ", ".join(parts)


def follow_edges(p: Plan, chosen: Selection, *, room: int,
                 run: Callable[[Plan, dict[str, list[int]], Selection], Selection | None]
                 ) -> Selection:
    """``chosen``, or the selection on a grown grid while its choice binds an edge that can
    grow (module docstring; at most :data:`MAX_ROUNDS` times). ``run(plan, sweep_grid,
    selection)`` sweeps ``sweep_grid`` with the focus and direct term of ``selection`` and
    chooses among those rows and the ones ``selection`` already scored, on ``plan`` (its grid
    the union of both); None when nothing of it succeeded. The sweep covers the new values
    of a grown horizon and the chosen one, the other horizon held at its chosen value, with
    every order (the rows of the other pairs are kept from before): a few pairs per round.
    The score's window stays that of the first sweep, so every row is scored alike.
    ``room``: the largest ``past + future`` of the identification data (three Hankel columns
    per row, or the largest pair of a default grid that needed fewer on a short record:
    :attr:`sysid.auto.Plan.room`)."""
    first = p.grid
    room = min(room, ROOM_X * (first["pasts"][-1] + first["futures"][-1]))
    for _ in range(MAX_ROUNDS):
        edges = binding_edges(chosen.best, chosen.result.ranked(require_stable=True), p.grid)
        grid = grown_grid(p.grid, edges, room=room, n_outputs=p.ident[0].n_outputs,
                          fixed=p.fixed, future=chosen.best.future)
        if grid is None:
            break
        swept = {f"{name}s": sorted(set(grid[f"{name}s"]) - set(p.grid[f"{name}s"])
                                    | {getattr(chosen.best, name)})
                 for name in ("past", "future")}
        swept["orders"] = grid["orders"]
        p = dataclasses.replace(p, grid=grid, scored_grid=p.scored_grid or first)
        grown = run(p, swept, chosen)
        if grown is None:
            break
        chosen = dataclasses.replace(
            grown, focus_note=chosen.focus_note, focus_scores=chosen.focus_scores,
            feedthrough_note=chosen.feedthrough_note,
            rule=f"{p.rule}; grid grown where the held-out score still rose at its edge: "
                 f"{describe(first, grid)}")
    return chosen
