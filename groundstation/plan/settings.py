"""The plan's tables for what runs alongside the flight: ``[live_id]``, identification while
the excitation flies (``docs/live-id.md``), and ``[parameters]``, firmware parameters set for the
flight and restored after it.

Read like the flight's own sections (:mod:`groundstation.plan.sections`): every reader takes a
:class:`TomlTable`, so its errors name the key and its line. The names are only checked for form
here; the flight checks them against the log blocks and the firmware's TOC before take-off.
A ``[parameters]`` value is also checked here against the type of a parameter the firmware is
known to have (:mod:`groundstation.plan.param_types`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from groundstation.plan.param_types import KNOWN_TYPES, value_problem
from groundstation.plan.toml import TomlTable, shown

__all__ = ["MAX_PARAMETERS", "LiveIdConfig", "read_live_id", "read_parameters"]


@dataclass(frozen=True)
class LiveIdConfig:
    """The plan's ``[live_id]`` table (every key optional; ``docs/live-id.md``): identify a
    model while the excitation flies. Channels name log streams (``"gyro"``), stream fields
    (``"gyro.z"``) or logged variables (``"motor.m1"``); horizons in grid samples; the update
    period in seconds of flight time."""

    inputs: tuple[str, ...] = ("motors",)
    outputs: tuple[str, ...] = ("gyro",)
    order: int = 8
    past: int = 60
    future: int = 17
    update_period: float = 1.0


_CHANNEL = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)?")


def _channel_names(t: TomlTable, key: str, default: tuple[str, ...]) -> tuple[str, ...]:
    raw = t.data.get(key, list(default))
    ok = isinstance(raw, list) and raw and all(isinstance(x, str) for x in raw)
    if not ok:
        raise t.src.error((*t.path, key), f"{shown(raw)} is not a valid value: {key} must be a "
                          'non-empty array of channel names, e.g. ["gyro"] or ["gyro.x", "gyro.y"]')
    for name in raw:
        if not _CHANNEL.fullmatch(name):
            raise t.src.error((*t.path, key), f"{shown(name)} is not a channel name; use a log "
                              'stream ("gyro"), STREAM.FIELD ("gyro.x") or a logged variable '
                              '("motor.m1")')
    if len(set(raw)) != len(raw):
        twice = sorted({x for x in raw if raw.count(x) > 1})
        raise t.src.error((*t.path, key), f"{shown(twice)} named twice; name each channel once")
    return tuple(raw)


def read_live_id(t: TomlTable) -> LiveIdConfig:
    """``[live_id]``: defaults in :class:`LiveIdConfig`. The names are checked against the
    flight's log blocks before take-off (:func:`groundstation.flight.liveid.check_live_id`)."""
    d = LiveIdConfig()
    t.allow(set(LiveIdConfig.__dataclass_fields__))
    inputs = _channel_names(t, "inputs", d.inputs)
    outputs = _channel_names(t, "outputs", d.outputs)
    both = sorted({y for y in outputs for x in inputs  # "motors" holds "motors.m1"
                   if y == x or y.startswith(f"{x}.") or x.startswith(f"{y}.")})
    if both:
        raise t.src.error((*t.path, "outputs"), f"{shown(both)} is both an input and an output; "
                          "pick one")
    cfg = LiveIdConfig(
        inputs=inputs, outputs=outputs,
        order=t.number("order", lo=1, hi=200, unit="states", kind=int, default=d.order),
        past=t.number("past", lo=1, hi=1000, unit="samples", kind=int, default=d.past),
        future=t.number("future", lo=2, hi=1000, unit="samples", kind=int, default=d.future),
        update_period=t.number("update_period", lo=0.1, hi=600.0, unit="s",
                               default=d.update_period),
    )
    if cfg.order > (cfg.future - 1) * len(outputs) and all("." in x for x in outputs):
        raise t.src.error((*t.path, "order"), f"order {cfg.order} exceeds (future - 1) x "
                          f"{len(outputs)} outputs = {(cfg.future - 1) * len(outputs)}; lower "
                          f"the order or raise future to {-(-cfg.order // len(outputs)) + 1}")
    return cfg


_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
MAX_PARAMETERS = 32


def read_parameters(t: TomlTable) -> tuple[tuple[str, float], ...]:
    """``[parameters]``: firmware parameters for the flight, ``GROUP.NAME = number`` (TOML's
    dotted keys, so ``pid_attitude.yaw_kd = 0.0`` or a ``[parameters.pid_attitude]`` table).
    Returned as ``("group.name", value)`` pairs in file order. A value the parameter's type
    cannot hold is refused here where the type is known offline
    (:data:`~groundstation.plan.param_types.KNOWN_TYPES`). The runner sets them after
    connecting, checked against the firmware's TOC, and restores the old values after the
    stop (:mod:`groundstation.flight.runner`)."""
    out: list[tuple[str, float]] = []
    for group, names in t.data.items():
        path = (*t.path, group)
        if not _IDENT.fullmatch(group) or not isinstance(names, dict):
            raise t.src.error(path, f"{shown(group)} is not a parameter group table; write "
                              "GROUP.NAME = number, e.g. pid_attitude.yaw_kd = 0.0")
        for name in names:
            if not _IDENT.fullmatch(name) or isinstance(names[name], dict):
                raise t.src.error((*path, name), f"{shown(f'{group}.{name}')} is not a firmware "
                                  "parameter name; write GROUP.NAME = number")
            value = TomlTable(t.src, path, names).get(name, float)
            full = f"{group}.{name}"
            ctype = KNOWN_TYPES.get(full)
            problem = "" if ctype is None else value_problem(value, ctype)
            if problem:
                raise t.src.error((*path, name), f"{problem}, the firmware's type for it; use "
                                  "a value in that range")
            out.append((full, value))
    if len(out) > MAX_PARAMETERS:
        raise t.src.error(t.path, f"{len(out)} parameters; at most {MAX_PARAMETERS}")
    return tuple(out)
