"""The simulated Crazyflie's CRTP services: one object turning request packets into replies.

:class:`CrtpPeer` answers what crazyflie-firmware answers (``modules/src/log.c``, ``param_logic.c``,
``crtpservice.c``, ``platformservice.c``, ``mem.c``, ``supervisor.c``, the commanders) and produces
the periodic log packets when the vehicle's firmware clock reaches them. It knows nothing about a
transport or threads: the ``sim://`` driver and the UDP server both feed it.

A packet is ``(header, payload)``: ``header = port << 4 | 0x0C | channel`` (one byte) and a payload
of at most 30 bytes. Log data packets are ``[block_id, t0, t1, t2, values...]`` with
``t = t0 + 256 t1 + 65536 t2`` the firmware tick in milliseconds modulo 2**24.

Deviations from the firmware, all of them defensive: non-finite setpoints and parameter values are
ignored (the firmware would feed them to its controllers), and an unknown log type in a block
request is refused with ``ENOEXEC`` (the firmware would read past its type table).
"""

from __future__ import annotations

import errno
import logging
import math
import struct
import zlib
from dataclasses import dataclass, field
from typing import Any

__all__ = [
    "LINK_TIMEOUT_MS",
    "LOG_MAX_BLOCKS",
    "LOG_MAX_LEN",
    "LOG_MAX_OPS",
    "PROTOCOL_VERSION",
    "CrtpPeer",
    "Packet",
    "crtp_header",
    "crtp_port",
]

logger = logging.getLogger(__name__)

Packet = tuple[int, bytes]
"""One CRTP packet: (header byte, payload of at most 30 bytes)."""

PROTOCOL_VERSION = 12
LOG_MAX_LEN = 26  # data bytes per log block (firmware LOG_MAX_LEN)
LOG_MAX_BLOCKS = 16
LOG_MAX_OPS = 128  # variables over all blocks (firmware LOG_MAX_OPS)
LINK_TIMEOUT_MS = 1000  # firmware: no packet for 1 s -> link down, logging reset
MAX_PAYLOAD = 30

P_CONSOLE, P_PARAM, P_COMMANDER, P_MEM, P_LOG, P_LOC, P_GENERIC = 0, 2, 3, 4, 5, 6, 7
P_SUPERVISOR, P_PLATFORM, P_LINKCTRL = 9, 13, 15

# cflib LogTocElement ids -> (struct code of the unsigned/float wire form, size, mask or None)
_LOG_TYPE_IDS = {"uint8_t": 1, "uint16_t": 2, "uint32_t": 3, "int8_t": 4, "int16_t": 5,
                 "int32_t": 6, "float": 7, "FP16": 8}
_LOG_WIRE = {1: ("B", 1), 2: ("H", 2), 3: ("I", 4), 4: ("B", 1), 5: ("H", 2), 6: ("I", 4),
             7: ("f", 4), 8: ("e", 2)}
# cflib ParamTocElement ids and struct codes
_PARAM_TYPE_IDS = {"int8_t": 0x00, "int16_t": 0x01, "int32_t": 0x02, "int64_t": 0x03,
                   "FP16": 0x05, "float": 0x06, "double": 0x07, "uint8_t": 0x08,
                   "uint16_t": 0x09, "uint32_t": 0x0A, "uint64_t": 0x0B}
_PARAM_CODES = {0x00: "b", 0x01: "h", 0x02: "i", 0x03: "q", 0x05: "e", 0x06: "f", 0x07: "d",
                0x08: "B", 0x09: "H", 0x0A: "I", 0x0B: "Q"}
_PARAM_RO = 0x40
_READ_ONLY_GROUPS = ("firmware",)  # read-only when the vehicle names none (PARAMS_READ_ONLY)

_FIRMWARE_VERSION = b"2025.02 (simulated)"
_DEVICE_NAME = b"Crazyflie 2.1 (sim)"


def crtp_header(port: int, channel: int) -> int:
    """The CRTP header byte of ``port`` and ``channel`` (the two link bits 0x0C set)."""
    return (port & 0x0F) << 4 | 0x0C | (channel & 0x03)


def crtp_port(header: int) -> int:
    """The port of a CRTP header byte."""
    return (header >> 4) & 0x0F


def _int_wire(value: float, size: int) -> int:
    """C's float-to-int cast then truncation to ``size`` bytes (two's complement)."""
    if value != value or value in (math.inf, -math.inf):
        return 0
    return int(value) & ((1 << (8 * size)) - 1)


def _encode(code: str, size: int, value: float) -> bytes:
    """One value in its wire form; floats out of range become +-inf like a C cast."""
    if code in "fe":
        try:
            return struct.pack("<" + code, value)
        except (OverflowError, struct.error):
            return struct.pack("<" + code, math.copysign(math.inf, value))
    return struct.pack("<" + code, _int_wire(value, size))


def _toc_crc(entries: list[tuple[str, int]], salt: bytes) -> int:
    """CRC32 of a TOC's names and types (a cache key for cflib; ``salt`` keeps log/param apart)."""
    blob = salt + b"".join(n.encode() + bytes([t]) for n, t in entries)
    return zlib.crc32(blob) & 0xFFFFFFFF


def _split(name: str) -> tuple[bytes, bytes]:
    group, _, var = name.partition(".")
    return group.encode(), var.encode()


@dataclass
class _Block:
    """One log block: its variables as (TOC index or -1 for raw memory, fetch type id)."""

    ops: list[tuple[int, int]] = field(default_factory=list)
    period_ms: int = 0  # 0: not started
    next_due_ms: int = 0

    def length(self) -> int:
        return sum(_LOG_WIRE[t][1] for _, t in self.ops)


class CrtpPeer:
    """The CRTP services of one simulated Crazyflie, answering for ``vehicle``.

    ``vehicle`` follows the :class:`groundstation.sim.vehicle.SimVehicle` interface. With no
    packet for ``link_timeout_ms`` (firmware ms) the link counts as down and logging is reset, as
    the firmware does; ``None`` leaves link liveness to the owner (:meth:`link_down`). Not
    thread-safe: the owner calls :meth:`handle`, :meth:`due_log_packets` and :meth:`console_packets`
    from the thread that also advances the vehicle.
    """

    def __init__(self, *, vehicle: Any, link_timeout_ms: int | None = LINK_TIMEOUT_MS) -> None:
        self.vehicle = vehicle
        self.link_timeout_ms = link_timeout_ms
        self._log_names = list(vehicle.LOG_VARIABLES)
        self._log_types = [_LOG_TYPE_IDS[t] for t in vehicle.LOG_VARIABLES.values()]
        self._param_names = list(vehicle.PARAMS)
        self._param_types = [_PARAM_TYPE_IDS[t] for t in vehicle.PARAMS.values()]
        read_only = getattr(vehicle, "PARAMS_READ_ONLY", None)
        self._param_ro = [n in read_only if read_only is not None
                          else n.split(".")[0] in _READ_ONLY_GROUPS for n in self._param_names]
        self._param_defaults = [vehicle.read_param(n) for n in self._param_names]
        for name in self._log_names + self._param_names:
            if 4 + len(name) + 1 > MAX_PAYLOAD:
                raise ValueError(f"TOC name {name!r} is too long for a CRTP packet; shorten it")
        self._log_crc = _toc_crc(list(zip(self._log_names, self._log_types, strict=True)), b"log")
        self._param_crc = _toc_crc(
            list(zip(self._param_names, self._param_types, strict=True)), b"param")
        self._blocks: dict[int, _Block] = {}
        self.last_rx_ms = vehicle.firmware_ms
        self.armed = True  # a CF2.x arms itself
        self.log_packets_sent = 0
        self._handlers = {
            P_LINKCTRL: self._linkctrl, P_PLATFORM: self._platform, P_LOG: self._log,
            P_PARAM: self._param, P_MEM: self._mem, P_COMMANDER: self._commander,
            P_GENERIC: self._generic_commander, P_SUPERVISOR: self._supervisor,
            P_LOC: self._localization,
        }

    # ------------------------------------------------------------------ entry points
    def handle(self, *, header: int, data: bytes) -> list[Packet]:
        """The replies to one incoming packet (never raises: bad requests get error codes or
        are ignored, as the firmware does)."""
        self.last_rx_ms = self.vehicle.firmware_ms
        handler = self._handlers.get(crtp_port(header))
        if handler is None:
            return []
        try:
            return handler(header & 0x03, bytes(data))
        except Exception:  # a malformed request must never take the vehicle down
            logger.debug("ignored malformed packet %02x %s", header, bytes(data).hex(),
                         exc_info=True)
            return []

    def next_due_ms(self) -> int | None:
        """Firmware ms at which the next log packet is due (``None``: no block running)."""
        due = [b.next_due_ms for b in self._blocks.values() if b.period_ms]
        return min(due) if due else None

    def due_log_packets(self) -> list[Packet]:
        """Log data packets whose time has come at the vehicle's current firmware ms.

        The timestamp is that firmware ms (24 bits). If no packet arrived for 1 s the firmware
        considers the link down and resets logging, which this mirrors.
        """
        now = self.vehicle.firmware_ms
        timeout = self.link_timeout_ms
        if self._blocks and timeout is not None and now - self.last_rx_ms > timeout:
            logger.info("no packet for %d ms: link down", now - self.last_rx_ms)
            self.link_down()
            return []
        out = []
        for block_id, block in self._blocks.items():
            if block.period_ms and block.next_due_ms <= now:
                out.append(self._log_data(block_id, block, now))
                block.next_due_ms += block.period_ms
                if block.next_due_ms <= now:  # fell behind by more than a period: skip
                    block.next_due_ms = now + block.period_ms
        self.log_packets_sent += len(out)
        return out

    def link_down(self) -> None:
        """The link is gone: the firmware stops and deletes every log block."""
        self._blocks.clear()

    def console_packets(self) -> list[Packet]:
        """The vehicle's new console text, in CONSOLE packets of up to 30 bytes."""
        text = "".join(line if line.endswith("\n") else line + "\n"
                       for line in self.vehicle.drain_console()).encode("utf-8", "replace")
        hdr = crtp_header(P_CONSOLE, 0)
        return [(hdr, text[i:i + MAX_PAYLOAD]) for i in range(0, len(text), MAX_PAYLOAD)]

    def supervisor_bits(self) -> int:
        """The supervisor state bitfield (cflib ``Supervisor`` bit order)."""
        v = self.vehicle
        armed = self.armed and not v.is_locked
        return (1 | armed << 1 | 1 << 2 | (armed and not v.is_locked) << 3
                | bool(v.is_flying) << 4 | bool(v.is_locked) << 6)

    # ------------------------------------------------------------------ link and platform
    def _linkctrl(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 0:  # echo (cflib's latency ping)
            return [(crtp_header(P_LINKCTRL, 0), data)]
        if ch == 1:  # source: the magic string tells cflib the protocol is versioned
            return [(crtp_header(P_LINKCTRL, 1), b"Bitcraze Crazyflie".ljust(MAX_PAYLOAD, b"\0"))]
        return []

    def _platform(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 0 and len(data) >= 2 and data[0] == 1:  # legacy arming request
            self._arm(bool(data[1]))
        elif ch == 1 and data:
            hdr = crtp_header(P_PLATFORM, 1)
            if data[0] == 0:
                return [(hdr, bytes([0, PROTOCOL_VERSION]))]
            if data[0] == 1:
                return [(hdr, b"\x01" + _FIRMWARE_VERSION)]
            if data[0] == 2:
                return [(hdr, b"\x02" + _DEVICE_NAME)]
        return []

    def _mem(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 0 and data and data[0] == 1:  # number of memories: none
            return [(crtp_header(P_MEM, 0), b"\x01\x00")]
        return []

    # ------------------------------------------------------------------ TOCs
    def _toc(self, *, port: int, data: bytes, names: list[str], types: list[int], crc: int,
             extra: bytes) -> list[Packet]:
        hdr = crtp_header(port, 0)
        cmd = data[0]
        if cmd == 3:  # info v2
            return [(hdr, struct.pack("<BHI", 3, len(names), crc) + extra)]
        if cmd == 1:  # info v1 (at most 255 entries)
            return [(hdr, struct.pack("<BBI", 1, min(len(names), 255), crc) + extra)]
        if cmd in (0, 2):
            wide = cmd == 2
            ident = struct.unpack_from("<H", data, 1)[0] if wide else data[1]
            if ident >= len(names):
                return [(hdr, bytes([cmd]))]
            group, var = _split(names[ident])
            head = struct.pack("<BHB", 2, ident, types[ident]) if wide else bytes(
                [0, ident, types[ident]])
            return [(hdr, head + group + b"\0" + var + b"\0")]
        return []

    # ------------------------------------------------------------------ logging
    def _log(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 0:
            return self._toc(port=P_LOG, data=data, names=self._log_names, types=self._log_types,
                             crc=self._log_crc, extra=bytes([LOG_MAX_BLOCKS, LOG_MAX_OPS]))
        if ch != 1 or not data:
            return []
        cmd = data[0]
        block_id = data[1] if len(data) > 1 else 0
        if cmd in (6, 7):
            ret = self._create_or_append(cmd == 6, block_id, data[2:])
        elif cmd == 2:
            ret = 0 if self._blocks.pop(block_id, None) is not None else errno.ENOENT
        elif cmd == 3:
            ret = self._start(block_id, data[2] * 10 if len(data) > 2 else 0)
        elif cmd == 4:
            block = self._blocks.get(block_id)
            ret = errno.ENOENT if block is None else 0
            if block is not None:
                block.period_ms = 0
        elif cmd == 5:
            self._blocks.clear()
            ret = 0
        else:  # v1 create/append (8-bit ids) are not offered at protocol 12; unknown commands
            ret = errno.ENOEXEC
        reply = [(crtp_header(P_LOG, 1), bytes([cmd, block_id, ret]))]
        if cmd == 3 and ret == 0 and len(data) > 2 and data[2] == 0:  # period 0: one-shot
            reply.append(self._log_data(block_id, self._blocks[block_id],
                                        self.vehicle.firmware_ms))
        return reply

    def _create_or_append(self, create: bool, block_id: int, settings: bytes) -> int:
        if create:
            if block_id in self._blocks:
                return errno.EEXIST
            if len(self._blocks) >= LOG_MAX_BLOCKS:
                return errno.ENOMEM
            self._blocks[block_id] = _Block()
        block = self._blocks.get(block_id)
        if block is None:
            return errno.ENOENT
        n_ops = sum(len(b.ops) for b in self._blocks.values())
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
            elif var_id >= len(self._log_names):
                return errno.ENOENT
            else:
                block.ops.append((var_id, fetch))
            n_ops += 1
            i += 1
        return 0

    def _start(self, block_id: int, period_ms: int) -> int:
        block = self._blocks.get(block_id)
        if block is None:
            return errno.ENOENT
        if period_ms > 0:
            block.period_ms = period_ms
            block.next_due_ms = self.vehicle.firmware_ms + period_ms
        return 0

    def _log_data(self, block_id: int, block: _Block, now_ms: int) -> Packet:
        t = now_ms & 0xFFFFFF
        parts = [bytes([block_id & 0xFF, t & 0xFF, (t >> 8) & 0xFF, t >> 16])]
        read = self.vehicle.read_log
        names = self._log_names
        for var_id, fetch in block.ops:
            code, size = _LOG_WIRE[fetch]
            value = read(names[var_id]) if var_id >= 0 else 0.0
            parts.append(_encode(code, size, value))
        return crtp_header(P_LOG, 2), b"".join(parts)

    # ------------------------------------------------------------------ parameters
    def _param(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 0:
            types = [t | (_PARAM_RO if ro else 0)
                     for t, ro in zip(self._param_types, self._param_ro, strict=True)]
            return self._toc(port=P_PARAM, data=data, names=self._param_names, types=types,
                             crc=self._param_crc, extra=b"")
        if ch == 3:
            return self._param_misc(data)
        ident = struct.unpack_from("<H", data, 0)[0]
        hdr = crtp_header(P_PARAM, ch)
        if ident >= len(self._param_names):
            return [(hdr, data[:2] + bytes([errno.ENOENT]))]
        code = _PARAM_CODES[self._param_types[ident]]
        name = self._param_names[ident]
        if ch == 1:  # read: [id, status 0, value]
            value = self.vehicle.read_param(name)
            return [(hdr, data[:2] + b"\0" + _encode(code, struct.calcsize(code), value))]
        if ch == 2:  # write: [id, value], echoed back
            size = struct.calcsize(code)
            if self._param_ro[ident] or len(data) < 2 + size:
                return []
            value = struct.unpack_from("<" + code, data, 2)[0]
            if not math.isfinite(value):
                return []
            self.vehicle.write_param(name, float(value))
            return [(hdr, data[:2 + size])]
        return []

    def _param_misc(self, data: bytes) -> list[Packet]:
        hdr = crtp_header(P_PARAM, 3)
        cmd = data[0]
        if cmd not in (7, 8):  # extended type v2, default value v2
            return []
        ident = struct.unpack_from("<H", data, 1)[0]
        if ident >= len(self._param_names):
            return [(hdr, data[:3] + bytes([errno.ENOENT]))]
        if cmd == 7:
            return [(hdr, data[:3] + b"\0\0")]
        code = _PARAM_CODES[self._param_types[ident]]
        value = _encode(code, struct.calcsize(code), self._param_defaults[ident])
        return [(hdr, data[:3] + b"\0" + value)]

    # ------------------------------------------------------------------ commanders and safety
    def _commander(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 0 and len(data) >= 14:
            roll, pitch, yawrate, thrust = struct.unpack_from("<fffH", data, 0)
            if math.isfinite(roll) and math.isfinite(pitch) and math.isfinite(yawrate):
                self.vehicle.commander_rpyt(roll=roll, pitch=pitch, yawrate=yawrate,
                                            thrust=thrust)
        return []

    def _generic_commander(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 0 and data[0] == 0:  # TYPE_STOP
            self.vehicle.commander_stop()
        elif ch == 0:
            logger.debug("generic setpoint type %d is not simulated; ignored", data[0])
        elif ch == 1 and data[0] == 0 and len(data) >= 5:  # notify setpoint stop
            remain = struct.unpack_from("<I", data, 1)[0]
            self.vehicle.commander_notify_stop(remain_valid_ms=remain)
        return []

    def _arm(self, armed: bool) -> None:
        self.armed = armed
        self.vehicle.arm(armed=armed)

    def _supervisor(self, ch: int, data: bytes) -> list[Packet]:
        hdr = crtp_header(P_SUPERVISOR, ch)
        cmd = data[0]
        if ch == 0 and cmd == 0x0C:
            return [(hdr, struct.pack("<BH", 0x8C, self.supervisor_bits()))]
        if ch != 1:
            return []
        if cmd == 0x01 and len(data) >= 2:
            self._arm(bool(data[1]))
            return [(hdr, bytes([0x81, 1, int(self.armed and not self.vehicle.is_locked)]))]
        if cmd == 0x02:  # crash recovery: a locked vehicle stays locked until rebooted
            return [(hdr, bytes([0x82, 0, int(not self.vehicle.is_locked)]))]
        if cmd == 0x03:  # emergency stop
            self.vehicle.commander_stop()
        return []

    def _localization(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 1 and data[0] == 3:  # legacy emergency stop
            self.vehicle.commander_stop()
        return []
