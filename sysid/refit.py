"""The chosen settings identified again on all the data, and the stable fallback.

After the sweep has chosen horizons and order on held-out data (:func:`sysid.auto.finish`), the
model returned is identified again on all the data (on the identification sessions when
validation sessions were given). That model is stable whenever the chosen row was: when all the
data tip a pole outside the unit circle (a near-integrating plant whose extra 30 % of data moves
one estimated mode out; seen on simulated flights at |z| = 1.1-1.4), the model the sweep scored
is returned instead, and a warning says so. The stability step's own warnings about the
model identified again are said only when it is the one returned.

Either way the model returned says which it is in ``provenance["selection"]``
(:func:`saved_as` words it for "model saved to ..."): ``identified_again`` (bool) and ``data``,
what it was identified on.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

from sysid.errors import DataError, OrderError
from sysid.grid import pair_flights
from sysid.methods import Method, Options
from sysid.model import StateSpaceModel
from sysid.sweep import SweepRow

if TYPE_CHECKING:  # sysid.auto imports this module
    from sysid.auto import Plan

__all__ = ["PROVENANCE_KEY", "final_model", "saved_as"]

#: The provenance entry saying what a selection's model is (module docstring).
PROVENANCE_KEY = "selection"


def final_model(p: Plan, best: SweepRow, warnings: list[str], *, method: Method,
                options: Options) -> StateSpaceModel:
    """``best``'s settings identified on all of ``p``'s data, or the scored model (module
    docstring); what was kept and why is appended to ``warnings``."""
    final = p.ident if p.given_validation else p.everything
    try:
        with _held_back("sysid.stability") as held:  # said only of the model kept
            model = method.identify(final, order=best.order, past=best.past,
                                    future=best.future, options=options)
    except (DataError, OrderError) as exc:  # all the data cannot hold what the grid's could
        warnings.append(f"identified again on all the data it failed ({exc}): kept the model "
                        f"the sweep scored ({_share(p)})")
        return _stamped(_scored_model(p, best, method=method, options=options),
                        again=False, data=_share(p))
    kept = _stable_choice(p, best, model, warnings, method=method, options=options)
    for record in held if kept is model else ():
        logging.getLogger(record.name).handle(record)
    return _stamped(kept, again=kept is model, data=(
        _all(p) if kept is model else _share(p)))


def saved_as(model: StateSpaceModel) -> str:
    """What a selection's model is, for the line that names where it was saved: "identified
    again on all the data", or "the model the sweep scored, identified on 3581 of the 5116
    samples" when the refit was not kept; "" for a model no selection stamped."""
    entry = model.provenance.get(PROVENANCE_KEY)
    if not isinstance(entry, dict) or not isinstance(entry.get("data"), str):
        return ""
    if entry.get("identified_again"):
        return f"identified again on {entry['data']}"
    return f"the model the sweep scored, {entry['data']}"


def _stamped(model: StateSpaceModel, *, again: bool, data: str) -> StateSpaceModel:
    return model.replace(provenance={**model.provenance, PROVENANCE_KEY: {
        "identified_again": again, "data": data}})


def _all(p: Plan) -> str:
    """What the model identified again was identified on, for a message."""
    return ("all the identification sessions' data" if p.given_validation else
            "all the data")


@contextlib.contextmanager
def _held_back(name: str) -> Iterator[list[logging.LogRecord]]:
    """The records logger ``name`` gets inside the block, held back from its handlers."""
    held: list[logging.LogRecord] = []

    def hold(record: logging.LogRecord) -> bool:
        held.append(record)
        return False

    logger = logging.getLogger(name)
    logger.addFilter(hold)
    try:
        yield held
    finally:
        logger.removeFilter(hold)


def _stable_choice(p: Plan, best: SweepRow, model: StateSpaceModel, warnings: list[str], *,
                   method: Method, options: Options) -> StateSpaceModel:
    """``model`` (identified on all the data), or the scored model when ``model`` has a pole
    outside the unit circle where the scored one had none; a warning in ``warnings`` says
    which."""
    if best.stable and not model.is_stable:
        scored = _scored_model(p, best, method=method, options=options)
        pole = f"{np.abs(model.poles()).max():.3f}"
        if scored.is_stable:
            warnings.append(f"identified again on all the data the model had a pole at |z| = "
                            f"{pole}: kept the stable model the sweep scored on the held-out "
                            f"data ({_share(p)})")
            model = scored
        else:  # rounding moved a pole of the scored model across: nothing better to offer
            warnings.append(f"identified again on all the data the model has a pole at "
                            f"|z| = {pole}")
    return model


def _scored_model(p: Plan, best: SweepRow, *, method: Method, options: Options
                  ) -> StateSpaceModel:
    """The model the sweep scored for ``best`` (kept with ``keep_models``, else identified
    again): its horizons on the identification data as the grid's common Hankel columns see
    them (:func:`sysid.grid.pair_flights`)."""
    if best.model is not None:
        return best.model
    grid = p.scored_grid or p.grid  # rows of a grown grid's sweeps keep their models
    trimmed = pair_flights(p.ident, past=best.past, future=best.future,
                           past_max=grid["pasts"][-1], future_max=grid["futures"][-1])
    return method.identify(list(trimmed), order=best.order, past=best.past,
                           future=best.future, options=options)


def _share(p: Plan) -> str:
    """How much data the scored model was identified on, for a message."""
    if p.given_validation:
        return "identified on the identification sessions, as the grid's common columns see them"
    n_ident = sum(d.n_samples for d in p.ident)
    n_all = sum(d.n_samples for d in p.everything)
    return f"identified on {n_ident} of the {n_all} samples"
