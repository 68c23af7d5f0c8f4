"""The former path of the flight plans, kept for callers: ``from groundstation.plans import ...``.

Plans now live in the package :mod:`groundstation.plan` (``toml.py``, ``sections.py``,
``variants.py``, ``schedule.py``, ``altitude.py``, ``excitation.py``); this module only re-exports
the names ``groundstation/plans.py`` used to define, the same objects.
"""

from groundstation.plan import (
    SETPOINT_CHANNELS,
    SHIPPED_PLANS_DIR,
    UNITS,
    ExcitationSpec,
    Phase,
    PhaseSpec,
    Plan,
    Safety,
    Schedule,
    VehicleLimits,
    find_plan,
    load_plan,
    parse_plan,
)

__all__ = [
    "SETPOINT_CHANNELS",
    "SHIPPED_PLANS_DIR",
    "UNITS",
    "ExcitationSpec",
    "Phase",
    "PhaseSpec",
    "Plan",
    "Safety",
    "Schedule",
    "VehicleLimits",
    "find_plan",
    "load_plan",
    "parse_plan",
]
