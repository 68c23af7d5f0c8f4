"""The UDP server with cflib's own UdpDriver: connect, log, fuzz, a client that vanishes."""

from __future__ import annotations

import contextlib
import random
import socket
import struct
import threading
import time

import cflib.crtp
import numpy as np
import pytest
from cflib.crtp.udpdriver import UdpDriver

from groundstation.errors import LinkError
from groundstation.sim import UdpServer
from groundstation.sim.crtp import crtp_header
from groundstation.sim.udp import CLIENT_SILENCE_S

from .helpers import Recorder, connect, free_udp_port
from .test_flight import hover_thrust


@pytest.fixture
def server():
    cflib.crtp.init_drivers()
    srv = UdpServer(port=free_udp_port(), seed=2)
    yield srv
    srv.close()
    time.sleep(0.05)
    assert not [t for t in threading.enumerate() if t.name.startswith("sim-")]


def test_cflib_udp_driver_connects_and_logs(server):
    uri = server.uris[0]
    assert uri.startswith("udp://127.0.0.1:")
    with connect(uri) as scf:
        assert isinstance(scf.cf.link, UdpDriver)  # cflib's, or the ground station's subclass
        assert float(scf.cf.param.get_value("pid_rate.roll_kp")) == pytest.approx(250.0)
        rec = Recorder(scf.cf, blocks={"gyro": ["gyro.x", "gyro.y", "gyro.z"]})
        time.sleep(1.0)  # real time
        rec.configs[0].stop()
    t, _ = rec.rows("gyro")
    assert len(t) >= 40 and set(np.diff(t)) == {20}


def test_scan_probe_and_port_in_use(server):
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(0.5)
        s.sendto(b"\xff", ("127.0.0.1", server.endpoints[0].port))
        assert s.recv(64) == b"\xff"
    with pytest.raises(LinkError, match="--port"):
        UdpServer(port=server.endpoints[0].port)


def _fuzz_datagrams(rng: random.Random, n: int) -> list[bytes]:
    out = []
    for _ in range(n):
        kind = rng.random()
        if kind < 0.3:  # random bytes, any length, some oversized or empty
            out.append(rng.randbytes(rng.choice([0, 1, 2, 5, 31, 32, 200, 1500])))
        elif kind < 0.8:  # well-formed header, bad ids and truncated requests on every service
            port = rng.choice([0, 2, 4, 5, 6, 7, 9, 13, 15])
            payload = bytes([rng.randrange(10)]) + struct.pack("<H", rng.choice(
                [0, 1, 300, 0xFFFF])) + rng.randbytes(rng.randrange(0, 28))
            out.append(bytes([crtp_header(port, rng.randrange(4))]) + payload[:30])
        else:  # commander packets with garbage floats (NaN, inf, huge)
            vals = [rng.choice([float("nan"), float("inf"), 1e30, -5.0, 3.0]) for _ in range(3)]
            out.append(bytes([crtp_header(3, 0)]) + struct.pack("<fffH", *vals,
                                                               rng.randrange(65536)))
    return out


def test_fuzz_then_a_normal_connect_still_works(server):
    port = server.endpoints[0].port
    sim = server.simulators[0]
    rng = random.Random(7)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.setblocking(False)
        for i, datagram in enumerate(_fuzz_datagrams(rng, 5000)):
            s.sendto(datagram, ("127.0.0.1", port))
            if i % 200 == 0:
                time.sleep(0.005)
                with contextlib.suppress(BlockingIOError):
                    while s.recv(64):
                        pass
    time.sleep(0.2)
    # thousands reach the server (the kernel may drop some of 5000 on a loaded machine)
    assert server.endpoints[0].datagrams > 1000 and server.endpoints[0].ignored > 100
    t0 = sim.clock.now()
    time.sleep(0.2)
    assert sim.running and sim.clock.now() > t0 + 0.1  # still simulating
    # The fuzzing socket held the link; closed, it is released when a packet sent to it bounces
    # (port unreachable), else once it has been silent for 1 s.
    endpoint = server.endpoints[0]
    if endpoint.client is not None:
        sim.clock.sleep_until(endpoint.client_seen_s + CLIENT_SILENCE_S + 0.05)
    with connect(server.uris[0]) as scf:
        assert scf.cf.log.toc.get_element_by_complete_name("motor.m1").ctype == "uint16_t"


def test_client_that_vanishes_mid_flight_triggers_the_watchdog(server):
    sim = server.simulators[0]
    with connect(server.uris[0]) as scf:
        cf = scf.cf
        Recorder(cf, blocks={"gyro": ["gyro.x", "gyro.y", "gyro.z"]})
        cf.commander.send_setpoint(0, 0, 0, 0)
        thrust = int(1.4 * hover_thrust(4.0))
        for _ in range(8):  # 0.8 s of real-time flight at 10 Hz
            cf.commander.send_setpoint(0, 0, 0, thrust)
            time.sleep(0.1)
        assert sim.vehicle.is_flying and any(sim.vehicle.motors_pwm)
        assert sim.peer.next_due_ms() is not None  # logging
        cf.link.close()  # the client vanishes: no stop setpoint, no more packets
        time.sleep(1.0)
        assert any(sim.vehicle.motors_pwm) and not sim.vehicle.is_locked  # levelled, still on
        time.sleep(1.3)
        assert sim.vehicle.is_locked and sim.vehicle.motors_pwm == (0, 0, 0, 0)
        assert sim.peer.next_due_ms() is None  # link down after 1 s: logging reset


def _free_run(n: int) -> int:
    """A port p with p .. p + n - 1 all free on 127.0.0.1."""
    for _ in range(50):
        base = free_udp_port()
        socks = []
        try:
            for k in range(n):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", base + k))
            return base
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise RuntimeError("no run of free ports")


def test_several_vehicles_on_consecutive_ports_bound_to_loopback():
    cflib.crtp.init_drivers()
    base = _free_run(3)
    srv = UdpServer(port=base, count=3, seed=4)
    try:
        assert [e.port for e in srv.endpoints] == [base, base + 1, base + 2]
        assert all(e.sock.getsockname()[0] == "127.0.0.1" for e in srv.endpoints)
        assert srv.uris == [f"udp://127.0.0.1:{base + k}" for k in range(3)]
        with connect(srv.uris[2]) as scf:  # the third vehicle answers a normal connect
            assert scf.cf.param.get_value("pid_rate.roll_kp") is not None
        assert srv.endpoints[2].datagrams > 0 and srv.endpoints[0].datagrams == 0
    finally:
        srv.close()


def test_one_client_at_a_time_others_are_ignored(server, caplog):
    """A second socket on the machine can neither fly the vehicle nor take its telemetry."""
    sim, endpoint = server.simulators[0], server.endpoints[0]
    addr = ("127.0.0.1", endpoint.port)
    commander = crtp_header(3, 0)
    with connect(server.uris[0]) as scf, socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        Recorder(scf.cf, blocks={"gyro": ["gyro.x", "gyro.y", "gyro.z"]})
        s.settimeout(0.3)
        for _ in range(20):  # unlock, then full thrust and a hard roll, for 2 s
            scf.cf.commander.send_setpoint(0, 0, 0, 0)  # the client keeps the link, grounded
            s.sendto(bytes([commander]) + struct.pack("<fffH", 0, 0, 0, 0), addr)
            s.sendto(bytes([commander]) + struct.pack("<fffH", 20, 0, 0, 60000), addr)
            time.sleep(0.1)
        assert not any(sim.vehicle.motors_pwm) and not sim.vehicle.is_flying
        assert endpoint.foreign >= 30  # the kernel may drop a few on a loaded machine
        with pytest.raises(TimeoutError):  # no telemetry went to the intruder
            s.recv(64)
        s.sendto(b"\xff", addr)  # a scan probe is still answered
        assert s.recv(64) == b"\xff"
    warnings = [r for r in caplog.records if "ignoring datagrams" in r.getMessage()]
    assert len(warnings) == 1  # logged once, counted after


@pytest.mark.parametrize("host", ["", "0.0.0.0", " ", "192.0.2.1"])
def test_a_host_others_reach_needs_allow_remote(host):
    with pytest.raises(LinkError, match=r"would let other machines fly .*--allow-remote"):
        UdpServer(host=host, port=free_udp_port())


def test_sim_command_refuses_a_wildcard_host_in_one_line():
    from click.testing import CliRunner

    from groundstation.cli import main

    result = CliRunner().invoke(main, ["sim", "--host", "0.0.0.0", "--duration", "0.1"])
    assert result.exit_code == 2
    assert result.output.strip().count("\n") == 0 and "--allow-remote" in result.output
