"""The former path of the excitation signals (PRBS, doublet, step, chirp), kept for callers:
``from sysid.excitation import prbs``.

They belong to the flight plan and now live in :mod:`groundstation.plan.excitation`. ``sysid``
never imports ``groundstation`` when it is imported itself (``docs/architecture.md``), so this
module re-exports lazily: the flying side is loaded on the first access to one of the names
``sysid/excitation.py`` used to define, and the objects are the same. One difference:
:class:`ExcitationError` is now a ``PlanError`` (a ``ValueError``), no longer a ``SysIdError``.
"""

from __future__ import annotations

from typing import Any

_MOVED = (
    "LFSR_TAPS",
    "ExcitationError",
    "chirp",
    "doublet",
    "mls_bits",
    "prbs",
    "prbs_period",
    "prbs_persistence_order",
    "prbs_shift",
    "register_length_for_period",
    "step",
)
__all__ = list(_MOVED)  # each name is looked up in the new home on first use


def __getattr__(name: str) -> Any:
    if name not in _MOVED:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from groundstation.plan import excitation  # lazy: docs/architecture.md, sysid.excitation row

    value = getattr(excitation, name)
    globals()[name] = value  # the next access is a plain lookup
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
