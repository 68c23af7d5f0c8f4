"""CrtpPeer on its own: raw request packets in, the firmware's replies out (no threads)."""

from __future__ import annotations

import errno
import struct
from typing import ClassVar

import pytest

from groundstation.sim.crtp import LOG_MAX_BLOCKS, CrtpPeer, crtp_header
from groundstation.sim.vehicle import SimVehicle

LOG_CTRL = crtp_header(5, 1)


@pytest.fixture
def peer() -> CrtpPeer:
    return CrtpPeer(vehicle=SimVehicle(seed=1))


def _log_id(peer: CrtpPeer, name: str) -> int:
    return list(peer.vehicle.LOG_VARIABLES).index(name)


def _create(peer: CrtpPeer, block: int, items: list[tuple[int, int]], cmd: int = 6) -> int:
    data = bytes([cmd, block]) + b"".join(struct.pack("<BH", t, i) for t, i in items)
    [(hdr, reply)] = peer.handle(header=LOG_CTRL, data=data)
    assert hdr == LOG_CTRL and reply[:2] == bytes([cmd, block])
    return reply[2]


def test_connect_handshake_answers(peer):
    [(_, magic)] = peer.handle(header=crtp_header(15, 1), data=b"\0")
    assert magic.startswith(b"Bitcraze Crazyflie")
    assert peer.handle(header=crtp_header(13, 1), data=b"\0") == [(crtp_header(13, 1), b"\0\x0c")]
    assert peer.handle(header=crtp_header(4, 0), data=b"\x01") == [(crtp_header(4, 0), b"\x01\0")]
    assert peer.handle(header=crtp_header(15, 0), data=b"ping1234") == [
        (crtp_header(15, 0), b"ping1234")]


def test_log_toc_item_and_crcs(peer):
    [(_, info)] = peer.handle(header=crtp_header(5, 0), data=b"\x03")
    count, log_crc, max_blocks, max_ops = struct.unpack("<xHIBB", info)
    assert count == len(SimVehicle.LOG_VARIABLES) and (max_blocks, max_ops) == (16, 128)
    [(_, pinfo)] = peer.handle(header=crtp_header(2, 0), data=b"\x03")
    assert struct.unpack("<xHI", pinfo)[1] != log_crc  # cflib caches both TOCs in one namespace
    ident = _log_id(peer, "motor.m2")
    [(_, item)] = peer.handle(header=crtp_header(5, 0), data=struct.pack("<BH", 2, ident))
    assert item == struct.pack("<BHB", 2, ident, 2) + b"motor\0m2\0"  # 2: uint16_t
    [(_, bad)] = peer.handle(header=crtp_header(5, 0), data=struct.pack("<BH", 2, 999))
    assert bad == b"\x02"  # the firmware's answer to an id past the end


def test_log_block_error_codes(peer):
    acc = _log_id(peer, "acc.x")
    assert _create(peer, 1, [(7, acc)] * 6) == 0  # 24 bytes fit
    assert _create(peer, 1, [(7, acc)]) == errno.EEXIST
    assert _create(peer, 1, [(2, acc)], cmd=7) == 0  # append: 26 bytes, the limit
    assert _create(peer, 1, [(1, acc)], cmd=7) == errno.E2BIG
    assert _create(peer, 2, [(7, acc)] * 7) == errno.E2BIG  # 28 bytes in one request
    assert _create(peer, 3, [(7, 999)]) == errno.ENOENT  # no such variable
    assert _create(peer, 4, [(0x0F, acc)]) == errno.ENOEXEC  # no such type
    assert _create(peer, 77, [(7, acc)], cmd=7) == errno.ENOENT  # append to no block
    for cmd in (2, 3, 4):  # delete / start / stop an unknown block
        [(_, reply)] = peer.handle(header=LOG_CTRL, data=bytes([cmd, 55, 10]))
        assert reply == bytes([cmd, 55, errno.ENOENT])
    [(_, reply)] = peer.handle(header=LOG_CTRL, data=bytes([9, 1]))
    assert reply == bytes([9, 1, errno.ENOEXEC])


def test_enomem_past_16_blocks_and_reset_frees(peer):
    acc = _log_id(peer, "acc.x")
    assert all(_create(peer, 100 + i, [(7, acc)]) == 0 for i in range(LOG_MAX_BLOCKS))
    assert _create(peer, 200, [(7, acc)]) == errno.ENOMEM
    assert peer.handle(header=LOG_CTRL, data=b"\x05") == [(LOG_CTRL, b"\x05\0\0")]
    assert _create(peer, 200, [(7, acc)]) == 0


def test_log_data_period_values_and_types(peer):
    v = peer.vehicle
    ids = [_log_id(peer, n) for n in ("motor.m1", "acc.z", "pm.vbat")]
    # motor.m1 fetched as its own uint16, acc.z as float, pm.vbat as int8 (a C cast: 4.1 -> 4)
    assert _create(peer, 9, [(2, ids[0]), (7, ids[1]), (4, ids[2])]) == 0
    peer.handle(header=LOG_CTRL, data=bytes([3, 9, 5]))  # 50 ms
    start = v.firmware_ms
    packets = []
    while v.firmware_ms < start + 500:
        v.advance(0.001)
        packets += peer.due_log_packets()
    assert len(packets) == 10
    stamps = [p[1][1] | p[1][2] << 8 | p[1][3] << 16 for p in packets]
    assert stamps == [start + 50 * (k + 1) for k in range(10)]
    hdr, data = packets[-1]
    assert hdr == crtp_header(5, 2) and data[0] == 9 and len(data) == 4 + 2 + 4 + 1
    m1, acc_z, vbat = struct.unpack("<Hfb", data[4:])
    assert m1 == 0 and acc_z == pytest.approx(v.read_log("acc.z"), abs=1e-6)
    assert vbat == int(v.read_log("pm.vbat"))
    peer.handle(header=LOG_CTRL, data=bytes([4, 9]))  # stop
    v.advance(0.2)
    assert peer.due_log_packets() == []


class _WrapVehicle:
    """Just enough of a vehicle to put the firmware clock near the 24-bit wrap."""

    LOG_VARIABLES: ClassVar[dict[str, str]] = {"acc.x": "float"}
    PARAMS: ClassVar[dict[str, str]] = {"pm.lowVoltage": "float"}
    firmware_ms = 2**24 - 30
    time_s = firmware_ms / 1000

    def read_log(self, name):
        return 0.5

    def read_param(self, name):
        return 3.2


def test_timestamps_wrap_at_24_bits():
    v = _WrapVehicle()
    peer = CrtpPeer(vehicle=v, link_timeout_ms=None)
    _create(peer, 1, [(7, 0)])
    peer.handle(header=LOG_CTRL, data=bytes([3, 1, 2]))
    stamps = []
    for _ in range(3):
        v.firmware_ms = peer.next_due_ms()
        [(_, data)] = peer.due_log_packets()
        stamps.append(data[1] | data[2] << 8 | data[3] << 16)
    assert stamps == [2**24 - 10, 10, 30]


def test_params_read_write_and_read_only(peer):
    names = list(SimVehicle.PARAMS)
    kp = names.index("pid_rate.roll_kp")
    [(_, reply)] = peer.handle(header=crtp_header(2, 1), data=struct.pack("<H", kp))
    assert reply[:3] == struct.pack("<HB", kp, 0)
    assert struct.unpack("<f", reply[3:])[0] == pytest.approx(250.0)
    write = struct.pack("<Hf", kp, 180.0)
    assert peer.handle(header=crtp_header(2, 2), data=write) == [(crtp_header(2, 2), write)]
    assert peer.vehicle.read_param("pid_rate.roll_kp") == pytest.approx(180.0)
    ro = names.index("firmware.revision0")
    [(_, item)] = peer.handle(header=crtp_header(2, 0), data=struct.pack("<BH", 2, ro))
    assert item[3] == 0x0A | 0x40  # uint32, read-only
    assert peer.handle(header=crtp_header(2, 2), data=struct.pack("<HI", ro, 5)) == []
    [(_, bad)] = peer.handle(header=crtp_header(2, 1), data=struct.pack("<H", 999))
    assert bad == struct.pack("<HB", 999, errno.ENOENT)
    nan = struct.pack("<Hf", kp, float("nan"))
    assert peer.handle(header=crtp_header(2, 2), data=nan) == []
    assert peer.vehicle.read_param("pid_rate.roll_kp") == pytest.approx(180.0)


def test_link_timeout_resets_logging(peer):
    _create(peer, 1, [(7, 0)])
    peer.handle(header=LOG_CTRL, data=bytes([3, 1, 10]))
    peer.vehicle.advance(0.5)
    assert len(peer.due_log_packets()) == 1
    peer.vehicle.advance(0.6)  # 1.1 s without a packet
    assert peer.due_log_packets() == [] and peer.next_due_ms() is None
