"""The CRTP wire as the simulated Crazyflie and the firmware-in-the-loop peer write it: the header
byte, the ports, values in their wire form, the TOC replies of the log and parameter services.

A packet is ``(header, payload)``: ``header = port << 4 | 0x0C | channel`` (one byte, the two
link bits 0x0C set as the firmware and cflib write them) and a payload of at most
:data:`MAX_PAYLOAD` bytes.
"""

from __future__ import annotations

import math
import struct
import zlib

__all__ = [
    "MAX_PAYLOAD",
    "Packet",
    "crtp_channel",
    "crtp_header",
    "crtp_port",
    "encode",
    "toc_crc",
    "toc_reply",
]

Packet = tuple[int, bytes]
"""One CRTP packet: (header byte, payload of at most 30 bytes)."""

MAX_PAYLOAD = 30

P_CONSOLE, P_PARAM, P_COMMANDER, P_MEM, P_LOG, P_LOC, P_GENERIC = 0, 2, 3, 4, 5, 6, 7
P_SUPERVISOR, P_PLATFORM, P_LINKCTRL = 9, 13, 15


def crtp_header(port: int, channel: int) -> int:
    """The CRTP header byte of ``port`` and ``channel`` (the two link bits 0x0C set)."""
    return (port & 0x0F) << 4 | 0x0C | (channel & 0x03)


def crtp_port(header: int) -> int:
    """The port of a CRTP header byte."""
    return (header >> 4) & 0x0F


def crtp_channel(header: int) -> int:
    """The channel of a CRTP header byte."""
    return header & 0x03


def _int_wire(value: float, size: int) -> int:
    """C's float-to-int cast then truncation to ``size`` bytes (two's complement)."""
    if value != value or value in (math.inf, -math.inf):
        return 0
    return int(value) & ((1 << (8 * size)) - 1)


def encode(code: str, size: int, value: float) -> bytes:
    """One value in its wire form (``code``: a struct code); floats out of range become +-inf
    like a C cast."""
    if code in "fe":
        try:
            return struct.pack("<" + code, value)
        except (OverflowError, struct.error):
            return struct.pack("<" + code, math.copysign(math.inf, value))
    return struct.pack("<" + code, _int_wire(value, size))


def toc_crc(entries: list[tuple[str, int]], salt: bytes) -> int:
    """CRC32 of a TOC's names and types (a cache key for cflib; ``salt`` keeps log/param apart)."""
    blob = salt + b"".join(n.encode() + bytes([t]) for n, t in entries)
    return zlib.crc32(blob) & 0xFFFFFFFF


def _split(name: str) -> tuple[bytes, bytes]:
    group, _, var = name.partition(".")
    return group.encode(), var.encode()


def toc_reply(*, port: int, data: bytes, names: list[str], types: list[int], crc: int,
              extra: bytes) -> list[Packet]:
    """The reply to a TOC request on channel 0 of ``port`` (log or parameters): info v1/v2
    (count, ``crc``, then ``extra``) or one item v1/v2 (id, type, group and name)."""
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
