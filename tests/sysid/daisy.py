"""The DaISy open-loop benchmark protocol of ``shared/reference/benchmarks.md``.

Remove each column's mean over the whole record; identify on the first 2/3, validate on the
last 1/3; simulate the deterministic model from x0 = 0 on the validation inputs; fit per output
``100 (1 - ||y - yhat|| / ||y - mean(y)||)`` averaged over outputs; best over orders 2..10 among
stable models, past = future = 20, D estimated. Used by ``tests/sysid/test_daisy.py`` and
``python -m bench daisy``, which also runs it on other sets' files (:func:`parse_extra`).
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

import sysid
from sysid.methods import METHODS
from tests.paths import SHARED

__all__ = ["DAISY", "EXTRA", "SETS", "SIPPY_BEST", "Candidate", "best_model", "candidates",
           "load", "parse_extra", "protocol_fit"]

DAISY = SHARED / "data" / "daisy"

#: set -> (input columns, output columns), 1-based as in benchmarks.md
SETS: dict[str, tuple[list[int], list[int]]] = {
    "dryer": ([1], [2]), "cstr": ([2], [3, 4]), "robot_arm": ([1], [2]), "flutter": ([1], [2]),
    "heating_system": ([2], [3]), "exchanger": ([2], [3]),
}
#: SIPPY 1.0.1's best figure per set (benchmarks.md), the bar
SIPPY_BEST = {"dryer": 77.05, "cstr": 87.91, "robot_arm": 47.18, "flutter": 29.45,
              "heating_system": 64.01, "exchanger": 62.86}
#: other sets by name: (file, input columns, output columns), 1-based (:func:`parse_extra`)
EXTRA: dict[str, tuple[Path, list[int], list[int]]] = {}
ORDERS = range(2, 11)
HORIZON = 20


def parse_extra(text: str) -> dict[str, tuple[Path, list[int], list[int]]]:
    """Sets given as ``NAME=FILE:INPUTS:OUTPUTS`` separated by ``;``, columns 1-based and
    comma-separated (``cd_arm=CD_player_arm.dat:1,2:3,4``); ValueError names a bad entry."""
    sets = {}
    for entry in filter(None, (e.strip() for e in text.split(";"))):
        try:
            name, spec = entry.split("=", 1)
            path, ins, outs = spec.rsplit(":", 2)
            columns = [[int(c) for c in part.split(",")] for part in (ins, outs)]
        except ValueError:
            raise ValueError(f"{entry!r}: expected NAME=FILE:INPUTS:OUTPUTS, columns 1-based "
                             "and comma-separated (cd_arm=CD_player_arm.dat:1,2:3,4)") from None
        if min(min(c) for c in columns) < 1:
            raise ValueError(f"{entry!r}: columns are 1-based")
        sets[name.strip()] = (Path(path), *columns)
    return sets


def load(name: str) -> tuple[sysid.IOData, sysid.IOData]:
    """``(identification, validation)`` of a DaISy set (or of :data:`EXTRA`), means removed
    over the whole record."""
    path, ins, outs = EXTRA[name] if name in EXTRA else (DAISY / f"{name}.dat", *SETS[name])
    table = np.loadtxt(path, ndmin=2)
    u = table[:, [i - 1 for i in ins]]
    y = table[:, [i - 1 for i in outs]]
    u, y = u - u.mean(axis=0), y - y.mean(axis=0)
    cut = 2 * len(u) // 3
    return (sysid.IOData(u=u[:cut], y=y[:cut], dt=1.0),
            sysid.IOData(u=u[cut:], y=y[cut:], dt=1.0))


def protocol_fit(model: sysid.StateSpaceModel, val: sysid.IOData) -> float:
    """Mean fit over outputs of the simulation from x0 = 0 (NaN if the model is unstable)."""
    if not model.is_stable:
        return float("nan")
    res = sysid.compare(model, val, x0="zero", warn=False)
    return float(np.mean(np.asarray(res)))


@dataclass(frozen=True)
class Candidate:
    """One of the project's ways to identify: a label and a function (data, order) -> model."""

    label: str
    identify: Callable[[sysid.IOData, int], sysid.StateSpaceModel]


def candidates(*, pem: bool = False) -> Iterator[Candidate]:
    """Every registered method (:data:`sysid.methods.METHODS`), each with prediction and
    simulation focus (and PEM if asked)."""
    for method, focus, refine in itertools.product(METHODS.values(),
                                                   ("prediction", "simulation"),
                                                   (False, True) if pem else (False,)):

        def identify(d: sysid.IOData, n: int, method=method, focus=focus, refine=refine
                     ) -> sysid.StateSpaceModel:
            return method.identify(d, order=n, past=HORIZON, future=HORIZON,
                                   options=method.options(feedthrough=True, focus=focus,
                                                          pem=refine))

        yield Candidate(f"{method.name} {focus}{' +pem' if refine else ''}", identify)


def best_model(name: str, *, pem: bool = False) -> tuple[float, str, int, dict[str, float]]:
    """``(best fit, candidate, order, best fit per candidate)`` over orders 2..10; when every
    model was refused, the candidate is the first reason."""
    ident, val = load(name)
    best: tuple[float, str, int] = (-np.inf, "", 0)
    refused = ""
    per: dict[str, float] = {}
    logging.getLogger("sysid").setLevel(logging.ERROR)
    try:
        for cand in candidates(pem=pem):
            top = -np.inf
            for n in ORDERS:
                try:
                    fit = protocol_fit(cand.identify(ident, n), val)
                except sysid.SysIdError as exc:
                    refused = refused or f"refused: {exc}"
                    continue
                if np.isfinite(fit):
                    top = max(top, fit)
                    if fit > best[0]:
                        best = (fit, cand.label, n)
            per[cand.label] = top
    finally:
        logging.getLogger("sysid").setLevel(logging.NOTSET)
    if not np.isfinite(best[0]):
        best = (best[0], refused or best[1], best[2])
    return (*best, per)
