"""Variants of a flight plan that keep its text honest (the session stores the text flown).

:func:`advance_prbs` gives a second realisation of a PRBS plan for validation flights: every PRBS
starts ``chips`` chips later in its own m-sequence. The lags between the axes (which make them
uncorrelated) are unchanged, and so are the period and the persistence of excitation; the input is
a different stretch of the sequence. The new seeds are written into the plan's TOML text (by
:func:`~groundstation.plan.toml.set_keys`, every other byte kept), which is parsed again, so
``plan.text`` is exactly what was flown.
"""

from __future__ import annotations

from typing import Any

from groundstation.errors import PlanError
from groundstation.plan import Plan, parse_plan
from groundstation.plan.excitation import advance_state, prbs_shift
from groundstation.plan.toml import set_keys

__all__ = ["advance_prbs", "advanced_seed", "reseed_prbs"]


def advanced_seed(*, register_length: int, seed: int, chips: int) -> int:
    """Register state ``chips`` chips after ``seed``: the seed's bits are the first n chips,
    least significant bit first, so the new seed is :math:`\\sum_i a_{d+i} 2^i`."""
    return advance_state(register_length=register_length, seed=seed, chips=chips)


def advance_prbs(plan: Plan, *, chips: int) -> Plan:
    """The same plan with every PRBS advanced by ``chips`` chips (see the module docstring)."""
    if chips < 0:
        raise PlanError(f"{plan.source}: PRBS advance {chips} must be >= 0 chips")
    expected: dict[tuple[int, str], int] = {}
    edits: list[tuple[tuple, Any, str]] = []
    for i, phase in enumerate(plan.phases):
        for exc in phase.excitation:
            if exc.signal != "prbs":
                continue
            new = expected[i, exc.axis] = advanced_seed(
                register_length=exc.register_length, seed=exc.seed, chips=chips
            )
            if new != exc.seed:  # a defaulted seed is added to its axis table
                edits.append((("phase", i, exc.axis, "seed"), new, ""))
    if not expected:
        raise PlanError(f"{plan.source}: plan '{plan.name}' has no PRBS to advance")
    header = f"# PRBS advanced by {chips} chips from the shipped plan (groundstation)\n"
    text = header + set_keys(plan.text, edits=edits)
    advanced = parse_plan(text=text, source=plan.source, name=plan.name)
    for i, phase in enumerate(advanced.phases):  # never fly the old realisation by mistake
        for exc in phase.excitation:
            if (i, exc.axis) in expected and exc.seed != expected[i, exc.axis]:
                raise PlanError(
                    f"{plan.source}: could not rewrite phase[{i}].{exc.axis}.seed "
                    f"(got {exc.seed}, wanted {expected[i, exc.axis]})"
                )
    return advanced


def reseed_prbs(plan: Plan, *, seed: int) -> Plan:
    """The same plan with its first PRBS starting from register state ``seed``: every PRBS is
    advanced by the chips that take the first one's seed to ``seed`` (:func:`advance_prbs`), so
    the lags between the axes are kept."""
    first = next((e for p in plan.phases for e in p.excitation if e.signal == "prbs"), None)
    if first is None:
        raise PlanError(f"{plan.source}: plan '{plan.name}' has no PRBS to seed")
    n = first.register_length
    if not 1 <= seed < (1 << n):
        raise PlanError(f"{plan.source}: PRBS seed {seed} is outside 1..{(1 << n) - 1} "
                        f"(a {n}-bit register)")
    chips = prbs_shift(register_length=n, seed_a=first.seed, seed_b=seed)
    return advance_prbs(plan, chips=chips)
