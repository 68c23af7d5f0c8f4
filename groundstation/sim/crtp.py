"""The simulated Crazyflie's CRTP services: one object turning request packets into replies.

:class:`CrtpPeer` answers what crazyflie-firmware answers (``modules/src/log.c``, ``param_logic.c``,
``crtpservice.c``, ``platformservice.c``, ``mem.c``, ``supervisor.c``, the commanders) and produces
the periodic log packets when the vehicle's firmware clock reaches them. It knows nothing about a
transport or threads: the ``sim://`` driver and the UDP server both feed it.

A packet is ``(header, payload)``: ``header = port << 4 | 0x0C | channel`` (one byte) and a payload
of at most 30 bytes (:mod:`groundstation.sim.crtp_wire`). The log service, its blocks and their
data packets, is :mod:`groundstation.sim.crtp_log`; this module dispatches by port and answers
the others: link control, platform, memory, parameters, the commanders and the supervisor.

Deviations from the firmware, all of them defensive: non-finite setpoints and parameter values are
ignored (the firmware would feed them to its controllers), and an unknown log type in a block
request is refused with ``ENOEXEC`` (the firmware would read past its type table).
"""

from __future__ import annotations

import errno
import logging
import math
import struct
from typing import Any

from groundstation.sim.crtp_log import LOG_MAX_BLOCKS, LOG_MAX_LEN, LOG_MAX_OPS, LogService
from groundstation.sim.crtp_wire import (
    MAX_PAYLOAD,
    P_COMMANDER,
    P_CONSOLE,
    P_GENERIC,
    P_LINKCTRL,
    P_LOC,
    P_LOG,
    P_MEM,
    P_PARAM,
    P_PLATFORM,
    P_SUPERVISOR,
    Packet,
    crtp_channel,
    crtp_header,
    crtp_port,
    encode,
    toc_crc,
    toc_reply,
)

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

PROTOCOL_VERSION = 12
LINK_TIMEOUT_MS = 1000  # firmware: no packet for 1 s -> link down, logging reset

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
        self.logs = LogService(vehicle=vehicle)
        self._param_names = list(vehicle.PARAMS)
        self._param_types = [_PARAM_TYPE_IDS[t] for t in vehicle.PARAMS.values()]
        read_only = getattr(vehicle, "PARAMS_READ_ONLY", None)
        self._param_ro = [n in read_only if read_only is not None
                          else n.split(".")[0] in _READ_ONLY_GROUPS for n in self._param_names]
        self._param_defaults = [vehicle.read_param(n) for n in self._param_names]
        for name in self.logs.names + self._param_names:
            if 4 + len(name) + 1 > MAX_PAYLOAD:
                raise ValueError(f"TOC name {name!r} is too long for a CRTP packet; shorten it")
        self._param_crc = toc_crc(
            list(zip(self._param_names, self._param_types, strict=True)), b"param")
        self.last_rx_ms = vehicle.firmware_ms
        self._handlers = {
            P_LINKCTRL: self._linkctrl, P_PLATFORM: self._platform, P_LOG: self.logs.handle,
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
            return handler(crtp_channel(header), bytes(data))
        except Exception:  # a malformed request must never take the vehicle down
            logger.debug("ignored malformed packet %02x %s", header, bytes(data).hex(),
                         exc_info=True)
            return []

    def next_due_ms(self) -> int | None:
        """Firmware ms at which the next log packet is due (``None``: no block running)."""
        return self.logs.next_due_ms()

    def due_log_packets(self) -> list[Packet]:
        """Log data packets whose time has come at the vehicle's current firmware ms.

        The timestamp is that firmware ms (24 bits). If no packet arrived for 1 s the firmware
        considers the link down and resets logging, which this mirrors.
        """
        now = self.vehicle.firmware_ms
        timeout = self.link_timeout_ms
        if self.logs.blocks and timeout is not None and now - self.last_rx_ms > timeout:
            logger.info("no packet for %d ms: link down", now - self.last_rx_ms)
            self.link_down()
            return []
        return self.logs.due_packets(now)

    @property
    def log_packets_sent(self) -> int:
        return self.logs.packets_sent

    def link_down(self) -> None:
        """The link is gone: the firmware stops and deletes every log block."""
        self.logs.blocks.clear()

    def console_packets(self) -> list[Packet]:
        """The vehicle's new console text, in CONSOLE packets of up to 30 bytes."""
        text = "".join(line if line.endswith("\n") else line + "\n"
                       for line in self.vehicle.drain_console()).encode("utf-8", "replace")
        hdr = crtp_header(P_CONSOLE, 0)
        return [(hdr, text[i:i + MAX_PAYLOAD]) for i in range(0, len(text), MAX_PAYLOAD)]

    def supervisor_bits(self) -> int:
        """The supervisor state bitfield (cflib ``Supervisor`` bit order: ``supervisor.info``)."""
        return self.vehicle.supervisor_info()

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

    # ------------------------------------------------------------------ parameters
    def _param(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 0:
            types = [t | (_PARAM_RO if ro else 0)
                     for t, ro in zip(self._param_types, self._param_ro, strict=True)]
            return toc_reply(port=P_PARAM, data=data, names=self._param_names, types=types,
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
            return [(hdr, data[:2] + b"\0" + encode(code, struct.calcsize(code), value))]
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
        value = encode(code, struct.calcsize(code), self._param_defaults[ident])
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
            return [(hdr, bytes([0x81, 1, int(self.vehicle.supervisor.armed)]))]
        if cmd == 0x02:  # crash recovery: a locked vehicle stays locked until rebooted
            return [(hdr, bytes([0x82, 0, int(not self.vehicle.is_locked)]))]
        self._emergency(cmd)
        return []

    def _localization(self, ch: int, data: bytes) -> list[Packet]:
        if ch == 1:  # the legacy emergency stop and its watchdog: the same codes
            self._emergency(data[0])
        return []

    def _emergency(self, cmd: int) -> None:
        """Emergency stop (3: locks the vehicle) and its watchdog's notification (4)."""
        if cmd == 0x03:
            self.vehicle.emergency_stop()
        elif cmd == 0x04:
            self.vehicle.emergency_stop_watchdog()
