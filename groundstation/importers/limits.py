"""What a log variable list must satisfy to become a session stream (checked in linear time),
and the name a stream gets from its variables.

A Crazyflie log variable is ``group.name`` (C identifiers, a few dozen characters); a log block
holds a handful of them, a uSD event a few dozen. The limits below are far above that and below
what one HDF5 dataset header can describe (about 600 fields of 64-character names).
"""

from __future__ import annotations

from collections.abc import Sequence

from groundstation.errors import SessionError

__all__ = ["MAX_NAME", "MAX_VARIABLES", "check_variables", "stream_name_of_groups"]

MAX_VARIABLES = 512
"""Variables per log block (one dataset's compound type)."""
MAX_NAME = 64
"""Characters per variable name ``group.name``."""


def check_variables(names: Sequence[str], *, where: str) -> None:
    """One-line :class:`SessionError` naming ``where`` and the column (1-based) unless every
    name is non-empty, printable, at most :data:`MAX_NAME` long, not empty after its group
    (``g.``) and unique, and there are at most :data:`MAX_VARIABLES` of them."""
    if len(names) > MAX_VARIABLES:
        raise SessionError(f"{where}: {len(names)} variables; at most {MAX_VARIABLES} fit one "
                           "log block (split the log)")
    seen: dict[str, int] = {}
    for col, name in enumerate(names, start=1):
        what = f"{where}: variable {col} {name[:MAX_NAME]!r}"
        if not name.strip():
            raise SessionError(f"{where}: variable {col} has an empty name")
        if len(name) > MAX_NAME:
            raise SessionError(f"{what}... is longer than {MAX_NAME} characters")
        if not name.isprintable():
            raise SessionError(f"{what} holds control characters")
        if not name.split(".", 1)[-1].strip():
            raise SessionError(f"{what} has an empty name after its group; expected group.name")
        if name in seen:
            raise SessionError(f"{what} appears twice (also variable {seen[name]})")
        seen[name] = col


def stream_name_of_groups(variables: Sequence[str]) -> str:
    """A name saying what a block holds: its log groups in order, ``a+b+c+d+2-more`` past four."""
    groups = list(dict.fromkeys(v.split(".", 1)[0] for v in variables))
    if len(groups) > 4:
        return "+".join(groups[:4]) + f"+{len(groups) - 4}-more"
    return "+".join(groups) or "log"
