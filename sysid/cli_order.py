"""The body of ``sysid order`` (its options and help are in :mod:`sysid.cli`)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.markup import escape

from cfcommon.cli import output_table
from sysid.auto import default_grid
from sysid.cli_support import console, load_flights, session_args
from sysid.methods import get_method
from sysid.order import information_criteria, singular_values, suggest_order

__all__ = ["IC_MAX_ORDER", "order_command"]

#: Largest order whose information criteria are computed (one model each).
IC_MAX_ORDER = 12


def _values(values: np.ndarray) -> list[float | None]:
    """Criteria for JSON: ``null`` for a failed order (NaN)."""
    return [None if np.isnan(v) else float(v) for v in values]


def order_command(session: Path, *, method: str, past: int | None, future: int | None,
                  show: int, as_json: bool, **opts: Any) -> None:
    """Singular values, information criteria and the suggested order of ``session``."""
    flights = load_flights([session], opts=opts, verb="choose the order from")
    meth = get_method(method)
    if past is None or future is None:  # the default grid refuses records too short for it
        grid = default_grid(flights, give="horizons (--past/--future)")
        past = grid["pasts"][-1] if past is None else past
        future = grid["futures"][-1] if future is None else future
    limit = meth.max_order(past=past, future=future, n_inputs=flights[0].n_inputs,
                           n_outputs=flights[0].n_outputs)
    sv = singular_values(flights, past=past, future=future, method=meth)
    ic = information_criteria(flights, orders=range(1, max(min(show, IC_MAX_ORDER, limit), 1)
                                                    + 1), past=past, future=future, method=meth)
    hint = suggest_order(sv, ic, show=show, max_order=limit)
    if as_json:
        click.echo(json.dumps({"session": str(session), "method": meth.name, "past": past,
                               "future": future, "max_order": limit,
                               "singular_values": sv.tolist(), "suggested_order": hint.order,
                               "suggestion": {
                                   "rule": hint.rule, "reason": hint.reason,
                                   "by_rule": hint.by_rule, "gap_decades": hint.gap_decades,
                                   "gap_clear": hint.gap_clear},
                               "information_criteria": {
                                   "orders": ic.orders.tolist(), "n_params": ic.n_params.tolist(),
                                   "aic": _values(ic.aic), "aicc": _values(ic.aicc),
                                   "bic": _values(ic.bic), "chosen": ic.chosen,
                                   "failed": {str(n): why for n, why in ic.failed.items()}}},
                              indent=1))
        return
    con = console()
    table = output_table("n", "singular value", "log10 gap to next", console=con,
                         title=f"{meth.name} p={past} f={future}, orders up to {limit} "
                               "(> = largest gap)")
    for i, value in enumerate(sv[: min(show, sv.size)]):
        gap = (f"{hint.gaps[i]:.2f}" + (" >" if i + 1 == hint.by_rule["gap"] else "")
               if i < hint.gaps.size else "")
        table.add_row(str(i + 1), f"{value:.4g}", gap,
                      style="bold" if i + 1 == hint.order else None)
    con.print(table)
    columns = ("n", "params", "AIC", "AICc", "BIC") + (("note",) if ic.failed else ())
    table = output_table(*columns, console=con,
                         title="information criteria (one-step errors; * = smallest)")
    for i, n in enumerate(ic.orders):
        if int(n) in ic.failed:  # the reason is text, not markup ([...] in it)
            table.add_row(str(n), str(ic.n_params[i]), "-", "-", "-",
                          escape(f"failed: {ic.failed[int(n)]}"))
            continue
        cells = [f"{v[i]:.1f}" + (" *" if ic.chosen[k] == n else "")
                 for k, v in (("aic", ic.aic), ("aicc", ic.aicc), ("bic", ic.bic))]
        table.add_row(str(n), str(ic.n_params[i]), *cells, *([""] if ic.failed else []),
                      style="bold" if n == hint.order else None)
    con.print(table)
    if ic.failed:
        con.print(f"{len(ic.failed)} of {ic.orders.size} orders could not be identified by "
                  f"{meth.name} at these horizons (note); the criteria compare the others")
    con.print(f"largest gap ({hint.gap_decades:.2f} decades) after s_{hint.by_rule['gap']}; "
              f"AIC picks {ic.chosen['aic']}, AICc {ic.chosen['aicc']}, BIC {ic.chosen['bic']}")
    con.print(f"suggested order: {hint.order}, by {hint.reason}")
    command = shlex.join(["sysid", "identify", str(session), "--method", meth.name,
                          "--past", str(past), "--future", str(future),
                          "--order", str(hint.order), *session_args(opts)])
    con.print(f"to identify with it: {command}; without --order and the horizons, validation "
              "on held-out data chooses them, which judges better", markup=False)
