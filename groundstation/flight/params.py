"""Firmware parameters a plan sets for its flight (``[parameters]``), and putting them back.

:func:`check_parameters` runs before anything is recorded: every name must be in the firmware's
parameter TOC, writable, and an integer where the firmware's type is one; the old values come
from the values cflib read at connect. :func:`write_parameters` writes values and waits for the
firmware to confirm each (its reply updates cflib's cache and calls the update callback). The
runner writes the plan's values before take-off and the old ones after the stop, on every path
out of the flight (:mod:`groundstation.flight.runner`).
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from groundstation.errors import GroundStationError, LinkError
from groundstation.plan.param_types import value_problem

__all__ = ["CONFIRM_TIMEOUT_S", "ParamChange", "check_parameters", "restore_after_flight",
           "set_for_flight", "typed_value", "write_parameters"]

log = logging.getLogger(__name__)

CONFIRM_TIMEOUT_S = 2.0
"""Longest wait for the firmware to confirm one written parameter."""
_FLOAT_TYPES = ("float", "double", "FP16")


def typed_value(text: Any, ctype: str) -> float | int:
    """A parameter value as cflib keeps it (its text) made a number of the TOC's C type;
    ``ValueError``/``TypeError`` for text that is not one."""
    return float(text) if ctype in _FLOAT_TYPES else int(text)


@dataclass(frozen=True)
class ParamChange:
    """One parameter of the plan: ``name`` (``group.name``), the plan's ``value`` and the
    firmware's value before the flight (``old``)."""

    name: str
    value: float | int
    old: float | int


def check_parameters(cf: Any, wanted: Sequence[tuple[str, float]]) -> list[ParamChange]:
    """The plan's ``(name, value)`` pairs against ``cf``'s parameter TOC (a connected cflib
    ``Crazyflie``). Raises :class:`LinkError` (one line) for a name the firmware lacks, a
    read-only one, or a value its type cannot hold (a fraction for an integer, beyond the
    type's range: :func:`groundstation.plan.param_types.value_problem`)."""
    changes = []
    for name, value in wanted:
        element = cf.param.toc.get_element_by_complete_name(name)
        if element is None:
            raise LinkError(f"plan [parameters]: the firmware has no parameter {name!r}; "
                            "remove it or check its name (cfclient's Parameters tab lists them)")
        if element.get_readable_access() == "RO":
            raise LinkError(f"plan [parameters]: {name} is read-only in the firmware")
        ctype = element.ctype
        problem = value_problem(value, ctype)
        if problem:
            raise LinkError(f"plan [parameters]: {name}: {problem}, its type in the firmware's "
                            "TOC; use a value in that range")
        if ctype not in _FLOAT_TYPES:
            value = int(value)
        group, _, short = name.partition(".")
        text = cf.param.values.get(group, {}).get(short)
        try:
            old = typed_value(text, ctype)
        except (TypeError, ValueError):
            raise LinkError(f"plan [parameters]: {name} was not read at connect ({text!r}); "
                            "reconnect") from None
        changes.append(ParamChange(name=name, value=value, old=old))
    return changes


def write_parameters(cf: Any, values: Sequence[tuple[str, float | int]], *,
                     timeout_s: float = CONFIRM_TIMEOUT_S) -> None:
    """Write each ``(name, value)`` and wait until the firmware confirms a value equal to it
    (float parameters to float32 precision). Raises :class:`LinkError` naming the first one
    not confirmed within ``timeout_s``."""
    for name, value in values:
        group, _, short = name.partition(".")
        done = threading.Event()
        got: list[str] = []

        def confirmed(_name: str, text: str, got: list[str] = got, done=done) -> None:
            got.append(text)
            done.set()

        cf.param.add_update_callback(group=group, name=short, cb=confirmed)
        try:
            cf.param.set_value(name, value)
            ok = done.wait(timeout_s)
        except (KeyError, AttributeError) as exc:
            raise LinkError(f"parameter {name}: cflib refused it ({exc})") from None
        finally:
            cf.param.remove_update_callback(group=group, name=short, cb=confirmed)
        try:
            echo = float(got[-1]) if ok else math.nan
        except ValueError:
            echo = math.nan
        if not math.isclose(echo, float(value), rel_tol=1e-6, abs_tol=1e-9):
            seen = f"it answered {got[-1]!r}" if got else f"no answer in {timeout_s:g} s"
            raise LinkError(f"parameter {name} = {value:g} not confirmed by the firmware "
                            f"({seen})")


def set_for_flight(cf: Any, changes: Sequence[ParamChange], *,
                   event: Callable[..., None]) -> str:
    """Write the plan's values; an event lists them. Returns "" or the cause to abort with."""
    if not changes:
        return ""
    try:
        write_parameters(cf, [(c.name, c.value) for c in changes])
    except GroundStationError as exc:
        return f"plan [parameters]: {exc}"
    event("parameters set for the flight: " + ", ".join(
        f"{c.name} = {c.value:g} (was {c.old:g})" for c in changes))
    return ""


def restore_after_flight(cf: Any, changes: Sequence[ParamChange], *, event: Callable[..., None],
                         link_up: bool) -> None:
    """Write the values from before the flight back (after the stop), with an event; never
    raises: a failure (or no link) is a warning event saying they stay until a restart."""
    names = ", ".join(f"{c.name} = {c.old:g}" for c in changes)
    why = "no link"
    if link_up:
        try:
            write_parameters(cf, [(c.name, c.old) for c in changes])
            event(f"parameters restored: {names}")
            return
        except Exception as exc:
            log.exception("restoring parameters failed")
            why = str(exc)
    event(f"parameters not restored ({why}): {names} until the Crazyflie restarts",
          level="warning", source="safety")
