"""The data of live identification (:mod:`groundstation.flight.liveid`): which log variables
it uses (``[live_id]`` inputs and outputs, checked against the log streams of a flight before
connecting, :func:`planned_streams`, and at its start, the streams as recorded), and
:class:`Feed`, one stream's rows on their way to the grid (firmware time unwrapped)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np

from cfsession.channels import Channel
from cfsession.channels import resolve_channels as _resolve
from cfsession.errors import ChannelError
from cfsession.schema import StreamSpec, log_block_spec
from groundstation.errors import PlanError
from groundstation.flight.link import ATTITUDE_BLOCK, BATTERY_BLOCK, BLOCK_PERIOD_S, FLIGHT_BLOCKS
from groundstation.flight.runner import ALTITUDE_BLOCK, altitude_block_period
from groundstation.plan import LiveIdConfig, Plan

__all__ = ["Channel", "Feed", "check_live_id", "planned_streams", "resolve_channels"]

_WRAP = 1 << 24  # log packets carry a 24-bit millisecond tick


def planned_streams(plan: Plan) -> list[StreamSpec]:
    """The log streams a flight of ``plan`` records (types as 'float': only names matter)."""
    blocks = [(n, v, BLOCK_PERIOD_S) for n, v in FLIGHT_BLOCKS.items()]
    blocks += [ATTITUDE_BLOCK, BATTERY_BLOCK]
    if plan.altitude_hold is not None:
        blocks.append((ALTITUDE_BLOCK, (plan.altitude_hold.variable,),
                       altitude_block_period(1.0 / plan.setpoint_rate_hz)))
    return [log_block_spec(name=n, variables=[(v, "float") for v in vs], period_s=p)
            for n, vs, p in blocks]


def resolve_channels(names: Sequence[str], *, streams: Sequence[StreamSpec],
                     role: Literal["input", "output"]) -> list[Channel]:
    """The log variables ``names`` select, in order, by the rule of offline identification
    (:func:`cfsession.channels.resolve_channels`: a log stream, ``stream.field``, a logged
    variable such as ``motor.m1`` or a variable group such as ``gyro``). One-line
    :class:`PlanError` otherwise."""
    try:
        return _resolve(names, streams=streams, role=role)
    except ChannelError as exc:
        if exc.problem == "unknown":
            raise PlanError(f"live_id {role} {exc.name!r}: no such log stream or variable; the "
                            f"flight logs {', '.join(exc.logged)} (name a stream, STREAM.FIELD, "
                            "a variable or a variable group)") from None
        raise PlanError(f"live_id: {exc}") from None


def check_live_id(config: LiveIdConfig, *, streams: Sequence[StreamSpec]
                  ) -> tuple[list[Channel], list[Channel], float]:
    """Inputs, outputs and the grid period for ``config`` on these log streams; one-line
    :class:`PlanError` for a name logged nowhere, a channel selected twice, channels logged
    at different rates or an order beyond the horizons' rank."""
    ins = resolve_channels(config.inputs, streams=streams, role="input")
    outs = resolve_channels(config.outputs, streams=streams, role="output")
    labels = [c.label for c in ins + outs]
    twice = sorted({x for x in labels if labels.count(x) > 1})
    if twice:
        raise PlanError(f"live_id: {twice} selected twice (inputs and outputs); name each once")
    periods = {s.name: s.period_s for s in streams if any(c.stream == s.name for c in ins + outs)}
    if len({round(p or 0.0, 9) for p in periods.values()}) != 1 or not all(periods.values()):
        rates = ", ".join(f"{n} every {1000 * (p or 0):g} ms" for n, p in sorted(periods.items()))
        raise PlanError(f"live_id: the channels are logged at different rates ({rates}); live "
                        "identification needs one rate (no anti-alias filter in flight)")
    m, ell, c = len(ins), len(outs), config
    limit = min((c.future - 1) * ell, c.past * (m + ell))
    if c.order > limit:
        raise PlanError(f"live_id: order {c.order} exceeds the rank available "
                        f"(min((future - 1) x {ell} outputs, past x {m + ell} channels) = "
                        f"{limit}); lower the order or raise the horizons")
    return ins, outs, float(next(iter(periods.values())))


class Feed:
    """One log stream's rows not yet used by the grid: host s, firmware s, selected values."""

    def __init__(self, *, columns: list[int]) -> None:
        self.columns = columns
        self.host = np.empty(0)
        self.fw = np.empty(0)
        self.values = np.empty((0, len(columns)))
        self.last_raw: int | None = None
        self.wraps = 0
        self.max_host = -np.inf  # host time of the newest row received (kept or not)
        self.offset = 0.0  # host - firmware time of the newest rows (latency included)

    def add(self, rows: Sequence[tuple]) -> None:
        a = np.asarray(rows, dtype=float)
        raw = a[:, 1].astype(np.int64)
        prev = raw[0] if self.last_raw is None else self.last_raw
        wraps = self.wraps + np.cumsum(np.diff(np.concatenate([[prev], raw])) < -(_WRAP // 2))
        self.last_raw, self.wraps = int(raw[-1]), int(wraps[-1])
        self.max_host = max(self.max_host, float(a[-1, 0]))
        fw = (raw + wraps * _WRAP) / 1000.0
        self.offset = float(np.median(a[:, 0] - fw))
        self.host = np.concatenate([self.host, a[:, 0]])
        self.fw = np.concatenate([self.fw, fw])
        self.values = np.concatenate([self.values, a[:, self.columns]])

    def keep(self, mask: np.ndarray) -> None:
        self.host, self.fw, self.values = self.host[mask], self.fw[mask], self.values[mask]
