"""The simulated Crazyflie's log service (port 5, crazyflie-firmware ``modules/src/log.c``): the
log TOC, the blocks cflib creates, starts and stops, and their periodic data packets.

Log data packets are ``[block_id, t0, t1, t2, values...]`` with ``t = t0 + 256 t1 + 65536 t2``
the firmware tick in milliseconds modulo 2**24, each value in the wire form its block asked for.
A block runs every ``period_ms`` from its start; one that fell behind by more than a period skips
to the next period from now. An unknown log type in a block request is refused with ``ENOEXEC``
(the firmware would read past its type table); raw-memory entries are logged as zero.
"""

from __future__ import annotations

import errno
import struct
from dataclasses import dataclass, field
from typing import Any

from groundstation.sim.crtp_wire import P_LOG, Packet, crtp_header, encode, toc_crc, toc_reply

__all__ = ["LOG_MAX_BLOCKS", "LOG_MAX_LEN", "LOG_MAX_OPS", "LogService"]

LOG_MAX_LEN = 26  # data bytes per log block (firmware LOG_MAX_LEN)
LOG_MAX_BLOCKS = 16
LOG_MAX_OPS = 128  # variables over all blocks (firmware LOG_MAX_OPS)

# cflib LogTocElement ids -> (struct code of the unsigned/float wire form, size, mask or None)
_LOG_TYPE_IDS = {"uint8_t": 1, "uint16_t": 2, "uint32_t": 3, "int8_t": 4, "int16_t": 5,
                 "int32_t": 6, "float": 7, "FP16": 8}
_LOG_WIRE = {1: ("B", 1), 2: ("H", 2), 3: ("I", 4), 4: ("B", 1), 5: ("H", 2), 6: ("I", 4),
             7: ("f", 4), 8: ("e", 2)}


@dataclass
class _Block:
    """One log block: its variables as (TOC index or -1 for raw memory, fetch type id)."""

    ops: list[tuple[int, int]] = field(default_factory=list)
    period_ms: int = 0  # 0: not started
    next_due_ms: int = 0

    def length(self) -> int:
        return sum(_LOG_WIRE[t][1] for _, t in self.ops)


class LogService:
    """The log blocks of one simulated Crazyflie, reading ``vehicle`` (``LOG_VARIABLES``,
    ``read_log``, ``firmware_ms``; :class:`groundstation.sim.vehicle.SimVehicle`)."""

    def __init__(self, *, vehicle: Any) -> None:
        self.vehicle = vehicle
        self.names = list(vehicle.LOG_VARIABLES)
        self.types = [_LOG_TYPE_IDS[t] for t in vehicle.LOG_VARIABLES.values()]
        self.crc = toc_crc(list(zip(self.names, self.types, strict=True)), b"log")
        self.blocks: dict[int, _Block] = {}
        self.packets_sent = 0

    def handle(self, ch: int, data: bytes) -> list[Packet]:
        """The replies to one packet on the log port, channel ``ch``."""
        if ch == 0:
            return toc_reply(port=P_LOG, data=data, names=self.names, types=self.types,
                             crc=self.crc, extra=bytes([LOG_MAX_BLOCKS, LOG_MAX_OPS]))
        if ch != 1 or not data:
            return []
        cmd = data[0]
        block_id = data[1] if len(data) > 1 else 0
        if cmd in (6, 7):
            ret = self._create_or_append(cmd == 6, block_id, data[2:])
        elif cmd == 2:
            ret = 0 if self.blocks.pop(block_id, None) is not None else errno.ENOENT
        elif cmd == 3:
            ret = self._start(block_id, data[2] * 10 if len(data) > 2 else 0)
        elif cmd == 4:
            block = self.blocks.get(block_id)
            ret = errno.ENOENT if block is None else 0
            if block is not None:
                block.period_ms = 0
        elif cmd == 5:
            self.blocks.clear()
            ret = 0
        else:  # v1 create/append (8-bit ids) are not offered at protocol 12; unknown commands
            ret = errno.ENOEXEC
        reply = [(crtp_header(P_LOG, 1), bytes([cmd, block_id, ret]))]
        if cmd == 3 and ret == 0 and len(data) > 2 and data[2] == 0:  # period 0: one-shot
            reply.append(self._data(block_id, self.blocks[block_id], self.vehicle.firmware_ms))
        return reply

    def next_due_ms(self) -> int | None:
        """Firmware ms at which the next log packet is due (``None``: no block running)."""
        due = [b.next_due_ms for b in self.blocks.values() if b.period_ms]
        return min(due) if due else None

    def due_packets(self, now: int) -> list[Packet]:
        """The data packets due at firmware ms ``now``, stamped with it."""
        out = []
        for block_id, block in self.blocks.items():
            if block.period_ms and block.next_due_ms <= now:
                out.append(self._data(block_id, block, now))
                block.next_due_ms += block.period_ms
                if block.next_due_ms <= now:  # fell behind by more than a period: skip
                    block.next_due_ms = now + block.period_ms
        self.packets_sent += len(out)
        return out

    def _create_or_append(self, create: bool, block_id: int, settings: bytes) -> int:
        if create:
            if block_id in self.blocks:
                return errno.EEXIST
            if len(self.blocks) >= LOG_MAX_BLOCKS:
                return errno.ENOMEM
            self.blocks[block_id] = _Block()
        block = self.blocks.get(block_id)
        if block is None:
            return errno.ENOENT
        n_ops = sum(len(b.ops) for b in self.blocks.values())
        count, i = len(settings) // 3, 0
        while i < count:
            fetch, var_id = struct.unpack_from("<BH", settings, 3 * i)
            fetch &= 0x0F
            if fetch not in _LOG_WIRE:
                return errno.ENOEXEC
            if block.length() + _LOG_WIRE[fetch][1] > LOG_MAX_LEN:
                return errno.E2BIG
            if n_ops >= LOG_MAX_OPS:
                return errno.ENOMEM
            if var_id == 0xFFFF:  # raw memory: the address follows; the simulator logs zero
                block.ops.append((-1, fetch))
                i += 2
            elif var_id >= len(self.names):
                return errno.ENOENT
            else:
                block.ops.append((var_id, fetch))
            n_ops += 1
            i += 1
        return 0

    def _start(self, block_id: int, period_ms: int) -> int:
        block = self.blocks.get(block_id)
        if block is None:
            return errno.ENOENT
        if period_ms > 0:
            block.period_ms = period_ms
            block.next_due_ms = self.vehicle.firmware_ms + period_ms
        return 0

    def _data(self, block_id: int, block: _Block, now_ms: int) -> Packet:
        t = now_ms & 0xFFFFFF
        parts = [bytes([block_id & 0xFF, t & 0xFF, (t >> 8) & 0xFF, t >> 16])]
        read = self.vehicle.read_log
        names = self.names
        for var_id, fetch in block.ops:
            code, size = _LOG_WIRE[fetch]
            value = read(names[var_id]) if var_id >= 0 else 0.0
            parts.append(encode(code, size, value))
        return crtp_header(P_LOG, 2), b"".join(parts)
