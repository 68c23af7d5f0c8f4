"""The log blocks of a flight: which variables are logged, how often, and the check that each
block can be created.

A flight logs the thesis' three 50 Hz blocks (:data:`FLIGHT_BLOCKS`), the battery and the attitude
slowly, and with a plan's ``[altitude_hold]`` its altitude variable at twice the setpoint rate
(:func:`flight_blocks`). :func:`plan_blocks` checks the logged variables against the TOC before
anything flies: each must exist, its type is taken from the TOC (``motor.m1`` is ``uint16_t`` or
``uint32_t`` depending on the firmware) and each block must fit the firmware's 26 data bytes per
packet: :math:`\\sum_i \\text{size}(\\text{type}_i) \\le 26`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from cfsession.schema import CFLIB_TYPES, StreamSpec, log_block_spec
from groundstation.errors import LinkError

__all__ = [
    "ALTITUDE_BLOCK",
    "ATTITUDE_BLOCK",
    "BATTERY_BLOCK",
    "BLOCK_PERIOD_S",
    "FLIGHT_BLOCKS",
    "LOG_MAX_BYTES",
    "LOW_POWER",
    "PM_STATE",
    "BlockPlan",
    "altitude_block_period",
    "flight_blocks",
    "plan_blocks",
    "positions",
]

LOG_MAX_BYTES = 26
"""Data bytes in one log packet (firmware ``LOG_MAX_LEN``, cflib ``LogConfig.MAX_LEN``)."""
BLOCK_PERIOD_S = 0.020
FLIGHT_BLOCKS: dict[str, tuple[str, ...]] = {
    "motors": ("motor.m1", "motor.m2", "motor.m3", "motor.m4"),
    "acc": ("acc.x", "acc.y", "acc.z"),
    "gyro": ("gyro.x", "gyro.y", "gyro.z"),
}
"""The thesis' three 50 Hz blocks (section 4.2.2): motor commands, accelerometer, gyro."""
BATTERY_BLOCK = ("battery", ("pm.vbat",), 0.5)
"""A slow block (name, variables, period s) for the take-off check and the battery's sag."""
PM_STATE = "pm.state"
"""The power management's state (``pm_stm32f4.c``), logged in the battery block where the TOC
has it: :data:`LOW_POWER` in flight is the battery running out (below ``pm.lowVoltage``, 3.2 V
by default, for 5 s; below ``pm.criticalLowVoltage``, 3.0 V, for 5 s the firmware shuts down,
in the air too)."""
LOW_POWER = 3
"""``pm.state`` lowPower (0 battery, 1 charging, 2 charged, 3 lowPower, 4 shutdown)."""
SUPERVISOR_INFO = "supervisor.info"
"""The supervisor's state bits (``supervisor.c``), logged in the battery block where the TOC
has it, for the take-off check."""
(CAN_ARM_BIT, ARMED_BIT, AUTO_ARM_BIT, CAN_FLY_BIT, FLYING_BIT, TUMBLED_BIT, LOCKED_BIT,
 CRASHED_BIT) = (1 << 0, 1 << 1, 1 << 2, 1 << 3, 1 << 4, 1 << 5, 1 << 6, 1 << 7)
"""Bits of :data:`SUPERVISOR_INFO`: can be armed now (pre-flight checks passed: an arming
request is taken only then), armed, arms itself (auto-arm), can fly (the motors may run: a
take-off needs armed and can fly), flying (state Flying or WarningLevelOut: the stop setpoint
is fed until it clears), the two that refuse a take-off: upside down, locked, and crashed
(a crash recovery request or a restart clears it)."""
ATTITUDE_BLOCK = ("attitude", ("stabilizer.roll", "stabilizer.pitch", "stabilizer.yaw"), 0.1)
"""The estimated attitude at the setpoint rate, to see roll/pitch setpoints against it (slow, so
the radio's budget stays with the thesis' three 50 Hz blocks)."""
ALTITUDE_BLOCK = "altitude"
"""Log block of the plan's ``[altitude_hold]`` variable (only when the plan has one)."""

_WIRE_BYTES = {"uint8_t": 1, "int8_t": 1, "uint16_t": 2, "int16_t": 2, "FP16": 2,
               "uint32_t": 4, "int32_t": 4, "float": 4}

TocType = Callable[[str], str | None]


@dataclass(frozen=True)
class BlockPlan:
    """A log block as it will be created: ``variables`` are ``(group.name, TOC type)``."""

    name: str
    variables: tuple[tuple[str, str], ...]
    period_s: float

    @property
    def n_bytes(self) -> int:
        """Data bytes per packet: the sum of the variables' wire sizes."""
        return sum(_WIRE_BYTES[t] for _, t in self.variables)

    def spec(self) -> StreamSpec:
        """The session stream this block is recorded to."""
        return log_block_spec(name=self.name, variables=self.variables, period_s=self.period_s)


def altitude_block_period(setpoint_period_s: float) -> float:
    """The altitude block's period: twice the setpoint rate, at least 10 ms."""
    return max(0.01, round(setpoint_period_s / 2, 2))


def plan_blocks(
    *, toc_type: TocType, blocks: Mapping[str, Sequence[str]], period_s: float,
) -> list[BlockPlan]:
    """Blocks with types from the TOC (``toc_type(name)``, ``None`` if absent), each checked.

    Raises :class:`LinkError` naming the variable missing from the TOC, a type cflib cannot log,
    or the block beyond :data:`LOG_MAX_BYTES`.
    """
    out = []
    for name, variables in blocks.items():
        typed = []
        for var in variables:
            ctype = toc_type(var)
            if ctype is None:
                raise LinkError(f"log variable {var} (block {name}) is not in the Crazyflie's "
                                "log TOC; update the firmware or log another variable")
            if ctype not in _WIRE_BYTES or ctype not in CFLIB_TYPES:
                raise LinkError(f"log variable {var} has TOC type {ctype!r}, which cannot be "
                                "logged; choose another variable")
            typed.append((var, ctype))
        block = BlockPlan(name=name, variables=tuple(typed), period_s=period_s)
        if block.n_bytes > LOG_MAX_BYTES:
            raise LinkError(f"log block {name} needs {block.n_bytes} bytes per packet, more than "
                            f"the {LOG_MAX_BYTES} a log packet holds; split it into two blocks")
        out.append(block)
    return out


def flight_blocks(*, toc_type: TocType, altitude_variable: str | None,
                  setpoint_period_s: float, warn: Callable[[str], None] = lambda _: None,
                  ) -> list[BlockPlan]:
    """Every block a flight logs, checked by :func:`plan_blocks`: :data:`FLIGHT_BLOCKS`, the
    battery with :data:`PM_STATE` and :data:`SUPERVISOR_INFO` where the TOC has them (left
    out, with ``warn``, when the TOC has no ``pm.vbat``: e.g. CrazySim's unpatched SITL;
    :data:`SUPERVISOR_INFO` is then logged with the attitude) and the attitude, and
    ``altitude_variable`` (a plan's altitude hold) at :func:`altitude_block_period`."""
    blocks = plan_blocks(toc_type=toc_type, blocks=FLIGHT_BLOCKS, period_s=BLOCK_PERIOD_S)
    info = (SUPERVISOR_INFO,) if toc_type(SUPERVISOR_INFO) is not None else ()
    state = (PM_STATE,) if toc_type(PM_STATE) is not None else ()
    name, variables, period = BATTERY_BLOCK
    slow = [(name, (*variables, *state, *info), period), ATTITUDE_BLOCK]
    if toc_type(BATTERY_BLOCK[1][0]) is None:  # supervisor.info with the attitude instead
        a_name, a_variables, a_period = ATTITUDE_BLOCK
        slow = [(a_name, (*a_variables, *info), a_period)]
        warn(f"no {BATTERY_BLOCK[1][0]} in the log TOC (no power management, e.g. an "
             "unpatched SITL build): battery check skipped")
    for name, variables, period in slow:
        blocks += plan_blocks(toc_type=toc_type, blocks={name: variables}, period_s=period)
    if altitude_variable is not None:  # altitude for the hold, at twice the setpoint rate
        blocks += plan_blocks(toc_type=toc_type, blocks={ALTITUDE_BLOCK: (altitude_variable,)},
                              period_s=altitude_block_period(setpoint_period_s))
    return blocks


def positions(blocks: Sequence[BlockPlan], variable: str) -> dict[str, int]:
    """``{block name: index of variable in its values}`` for the blocks that log ``variable``."""
    return {b.name: [v for v, _ in b.variables].index(variable) for b in blocks
            if any(v == variable for v, _ in b.variables)}
