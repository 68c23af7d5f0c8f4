"""The sim:// link end to end with the real cflib: connection, TOCs, log blocks, faults."""

from __future__ import annotations

import errno
import struct
import threading

import numpy as np
import pytest
from cflib.crazyflie.log import LogConfig
from cflib.crtp.crtpstack import CRTPPacket

import groundstation.sim as gsim
from groundstation.errors import LinkError
from groundstation.flight.clock import clock_for_uri
from groundstation.sim.vehicle import SimVehicle

from .helpers import BLOCKS, Recorder, connect


def test_fully_connected_tocs_and_params(sim_uri):
    fully = threading.Event()
    with connect(sim_uri) as scf:
        cf = scf.cf
        cf.fully_connected.add_callback(lambda uri: fully.set())
        assert scf.is_params_updated()  # fully_connected has fired
        for name, ctype in SimVehicle.LOG_VARIABLES.items():
            assert cf.log.toc.get_element_by_complete_name(name).ctype == ctype
        assert cf.log.toc.get_element_by_complete_name("motor.m1").ctype == "uint16_t"
        assert cf.log.toc.get_element_by_complete_name("gyro.y").ctype == "float"
        vehicle = gsim.instance(sim_uri).vehicle
        for name, ctype in SimVehicle.PARAMS.items():
            element = cf.param.toc.get_element_by_complete_name(name)
            assert element.ctype == ctype
            assert float(cf.param.get_value(name)) == pytest.approx(vehicle.read_param(name))
        assert cf.param.toc.get_element_by_complete_name("firmware.revision0").access == 1
        done = threading.Event()
        cf.param.add_update_callback(group="pid_rate", name="pitch_kp",
                                     cb=lambda name, value: done.set())
        cf.param.set_value("pid_rate.pitch_kp", 199.5)
        assert done.wait(5)
        assert vehicle.read_param("pid_rate.pitch_kp") == pytest.approx(199.5)
        assert cf.platform.get_protocol_version() == 12
    assert not gsim.instance(sim_uri).running  # closing the link switched it off


def test_clock_for_uri_is_the_simulation_clock(sim_uri):
    with connect(sim_uri):
        sim = gsim.instance(sim_uri)
        clock = clock_for_uri(sim_uri)
        assert clock is sim.clock and clock.speed == 20
        t0 = clock.now()
        clock.sleep_until(t0 + 2.0)
        assert sim.vehicle.time_s >= t0 + 2.0 and clock.now() >= t0 + 2.0


def test_three_50hz_blocks_deliver_with_20ms_spacing(sim_uri):
    with connect(sim_uri) as scf:
        clock = gsim.instance(sim_uri).clock
        rec = Recorder(scf.cf, blocks=BLOCKS)
        clock.sleep_until(clock.now() + 10.0)
        for conf in rec.configs:
            conf.stop()
    for name in BLOCKS:
        t, values = rec.rows(name)
        assert t[-1] - t[0] >= 9_500, name  # the blocks start a few round trips in
        assert len(t) >= 0.99 * ((t[-1] - t[0]) / 20 + 1), name
        assert set(np.diff(t)) == {20}, name
        assert values.shape[1] == len(BLOCKS[name])
    _, acc = rec.rows("acc")
    assert np.mean(acc[:, 2]) == pytest.approx(1.0, abs=0.05)  # at rest on the ground: +1 g
    _, motors = rec.rows("motors")
    assert not motors.any()


def _log_replies(cf) -> tuple[list[bytes], threading.Event]:
    replies: list[bytes] = []
    got = threading.Event()

    def on_packet(pk):
        if pk.channel == 1:
            replies.append(bytes(pk.data))
            got.set()

    cf.add_port_callback(5, on_packet)
    return replies, got


def _send_log_ctrl(cf, data: bytes, replies, got) -> bytes:
    got.clear()
    n = len(replies)
    cf.send_packet(CRTPPacket(0x51, data))  # LOG port 5, control channel 1
    assert got.wait(5)
    return replies[n]


def test_e2big_for_oversized_block_and_cflib_refuses_it(sim_uri):
    with connect(sim_uri) as scf:
        cf = scf.cf
        big = LogConfig(name="big", period_in_ms=20)
        for var in ("acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z", "pm.vbat"):
            big.add_variable(var)
        with pytest.raises(AttributeError, match="too large"):  # cflib: 28 > 26 bytes
            cf.log.add_config(big)
        replies, got = _log_replies(cf)
        ident = cf.log.toc.get_element_id("acc.x")
        request = bytes([6, 60]) + struct.pack("<BH", 7, ident) * 7
        assert _send_log_ctrl(cf, request, replies, got) == bytes([6, 60, errno.E2BIG])


def test_enomem_past_16_blocks(sim_uri):
    with connect(sim_uri) as scf:
        cf = scf.cf
        replies, got = _log_replies(cf)
        ident = cf.log.toc.get_element_id("pm.vbat")
        for block in range(16):
            request = bytes([6, 100 + block]) + struct.pack("<BH", 7, ident)
            assert _send_log_ctrl(cf, request, replies, got)[2] == 0
        request = bytes([6, 120]) + struct.pack("<BH", 7, ident)
        assert _send_log_ctrl(cf, request, replies, got) == bytes([6, 120, errno.ENOMEM])


def test_drop_fault_shows_as_timestamp_gaps(sim_uri):
    uri = sim_uri + "&drop=0.1&seed=4"
    with connect(uri) as scf:
        sim = gsim.instance(uri)
        quality: list[float] = []  # reported as a radio link reports it, through cflib
        scf.cf.link_statistics.link_quality_updated.add_callback(quality.append)
        rec = Recorder(scf.cf, blocks={"gyro": BLOCKS["gyro"]})
        sim.clock.sleep_until(sim.clock.now() + 20.0)
        rec.configs[0].stop()
        sim.clock.sleep_until(sim.clock.now() + 0.2)
        t, _ = rec.rows("gyro")
        dropped = sim.dropped_packets
    gaps = np.diff(t)
    assert set(gaps % 20) == {0} and gaps.max() > 20
    missing = int(np.sum(gaps // 20 - 1))
    assert 0 <= dropped - missing <= 3  # drops before the first / after the last are invisible
    assert missing / (len(t) + missing) == pytest.approx(0.1, abs=0.03)
    assert len(quality) >= 5 and np.mean(quality) == pytest.approx(90.0, abs=4.0)


def test_latency_fault_delays_replies_in_simulation_time(sim_uri):
    uri = sim_uri + "&latency_ms=300"
    with connect(uri) as scf:
        clock = gsim.instance(uri).clock
        replies, got = _log_replies(scf.cf)
        t0 = clock.now()
        assert _send_log_ctrl(scf.cf, bytes([4, 99]), replies, got) == bytes([4, 99, 2])
        assert clock.now() - t0 >= 0.3 - 1e-9  # exactly 0.3 may round below it (42.009 - 41.709)


def test_cut_link_fires_connection_lost_and_vehicle_runs_on(sim_uri):
    uri = sim_uri + "&cut_at=30"
    lost = threading.Event()
    with connect(uri) as scf:
        scf.cf.connection_lost.add_callback(lambda uri, msg: lost.set())
        sim = gsim.instance(uri)
        assert sim.vehicle.time_s < 30.0, "connecting took too long for this test"
        assert lost.wait(10)
        assert sim.running and sim.vehicle.time_s >= 30.0
        sim.clock.sleep_until(30.5)
        assert sim.running  # the vehicle does not notice a lost link


def test_bad_uri_options_are_one_line_errors():
    with pytest.raises(LinkError, match="speed"):
        gsim.parse_uri("sim://0?speed=fast")
    with pytest.raises(LinkError, match="unknown sim:// option 'sped'"):
        gsim.parse_uri("sim://0?sped=20")
    with pytest.raises(LinkError, match="option 'speed' given twice"):  # the last won: a
        gsim.parse_uri("sim://0?speed=inf&seed=1&speed=1")  # flat-out flight in real time
    opts = gsim.parse_uri("sim://3?speed=20&seed=3&drop=0.05&latency_ms=20&cut_at=12.5")
    assert (opts.address, opts.speed, opts.seed) == ("3", 20.0, 3)
    assert (opts.faults.drop, opts.faults.latency_ms, opts.faults.cut_at) == (0.05, 20.0, 12.5)


def test_install_is_idempotent_and_first():
    import cflib.crtp

    gsim.install()
    gsim.install()
    assert cflib.crtp.CLASSES[0] is gsim.SimDriver
    assert cflib.crtp.CLASSES.count(gsim.SimDriver) == 1
