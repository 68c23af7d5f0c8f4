"""The physics peer's packets, checked against the firmware's wire format (no firmware needed):
known answers at rest and for the ``sim://`` vehicle's hover PWM."""

from __future__ import annotations

import math
import struct

import pytest

from groundstation.sim.physics import GRAVITY_M_S2, VehicleConstants, motor_thrust_n
from groundstation.sim.physics_peer import (
    BARO_EVERY,
    POSE_EVERY,
    PhysicsPeer,
    crtp_header,
    parse_motor_packet,
)
from groundstation.sim.sensors import NoiseModel
from groundstation.sim.vehicle import SimVehicle

QUIET = NoiseModel(gyro_rest_dps=(0.0,) * 3, gyro_vib_dps=(0.0,) * 3, acc_rest_g=(0.0,) * 3,
                   acc_vib_g=(0.0,) * 3, gyro_bias_dps=0.0, acc_bias_g=0.0)


def test_imu_at_rest_reads_one_g_up_and_no_rotation():
    peer = PhysicsPeer(noise=QUIET)
    pk = peer.step()
    header, kind, ax, ay, az, gx, gy, gz = struct.unpack("<BB3h3h", pk)
    assert (header, kind) == (0x9C, 0)  # port 9, channel 0, link bits set; type 0 = gyro+acc
    assert (ax, ay, az, gx, gy, gz) == (0, 0, 2048, 0, 0, 0)
    assert peer.time_s == pytest.approx(0.001)


def test_default_noise_at_rest_is_small_enough_for_the_gyro_bias_estimate():
    """The firmware takes its gyro bias from still samples whose variance is below 5000 LSB²."""
    peer = PhysicsPeer(seed=3)
    gyro = [struct.unpack("<BB3h3h", peer.step())[5:] for _ in range(1024)]
    for axis in zip(*gyro, strict=True):
        mean = sum(axis) / len(axis)
        assert sum((g - mean) ** 2 for g in axis) / len(axis) < 5000


def test_hover_pwm_holds_and_more_climbs():
    peer = PhysicsPeer(noise=QUIET)
    hover = peer.hover_pwm()
    assert 30000 < hover < 45000  # the project's CF2.1
    peer.set_motors((hover + 4000,) * 4)
    for _ in range(1000):
        pk = peer.step()
    assert peer.body.z > 0.05 and not peer.body.on_ground
    az = struct.unpack("<BB3h3h", pk)[4]
    assert az > 2048  # climbing: specific force above 1 g
    pose = struct.unpack("<BB7f", peer.pose_packet())
    assert pose[:2] == (crtp_header(port=6, channel=1), 8)
    assert pose[4] == pytest.approx(peer.body.z) and pose[8] == pytest.approx(1.0, abs=1e-3)


def test_barometer_is_the_standard_atmosphere():
    peer = PhysicsPeer(noise=QUIET)
    peer.body.z = 100.0
    header, kind, p, _temp, asl = struct.unpack("<BB3f", peer.barometer_packet())
    assert (header, kind, asl) == (0x9C, 2, 100.0)
    assert p == pytest.approx(1013.25 * math.exp(-100.0 * 0.0289644 * GRAVITY_M_S2
                                                 / (8.31446 * 288.15)), rel=1e-3)
    assert (BARO_EVERY, POSE_EVERY) == (20, 5)  # 50 Hz and 200 Hz at the 1 kHz step


def test_motor_packets_are_recognised_and_nothing_else():
    assert parse_motor_packet(struct.pack("<B4H", 0x9C, 1, 2, 3, 65535)) == (1, 2, 3, 65535)
    assert parse_motor_packet(struct.pack("<B4H", 0x90, 1, 2, 3, 4)) == (1, 2, 3, 4)  # no link
    assert parse_motor_packet(bytes([0x9C, 1])) is None  # "gyro bias found"
    assert parse_motor_packet(struct.pack("<B4H", 0x5C, 1, 2, 3, 4)) is None  # port 5: log
    assert parse_motor_packet(struct.pack("<B4HB", 0x9C, 1, 2, 3, 4, 0)) is None


def test_motor_commands_are_battery_compensated_as_on_sim():
    """The SITL build leaves out the firmware's battery compensation; the peer applies it, so a
    command gives the thrust it gives on ``sim://``, fresh or sagging battery alike."""
    sim_hover = SimVehicle().hover_thrust()
    for vbat in (4.15, 3.7):
        peer = PhysicsPeer(noise=QUIET, vbat_full=vbat)
        assert abs(peer.hover_pwm() - sim_hover) <= 2, vbat
    thrust, raw = [], []
    for vbat in (4.15, 3.7):
        peer = PhysicsPeer(noise=QUIET, vbat_full=vbat)
        peer.set_motors((sim_hover,) * 4)
        thrust.append(sum(peer._targets))
        assert peer.pwm == (sim_hover,) * 4  # the command, as the firmware logs it
        raw.append(4 * motor_thrust_n(pwm=sim_hover, vbat_v=peer.battery.voltage_v,
                                      c=peer.const))
    assert thrust[1] == pytest.approx(thrust[0], rel=1e-3)
    assert raw[1] < 0.85 * raw[0]  # the command taken as the duty: 18 % less thrust at 3.7 V
    weight = VehicleConstants().mass_kg * GRAVITY_M_S2
    assert thrust[0] == pytest.approx(weight, rel=2e-3)
