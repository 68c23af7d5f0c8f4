"""Simulator speed: in-process real-time factor, and the UDP server's CPU use in real time.

1. In process, with the full 1 kHz physics and the thesis' three 50 Hz log blocks consumed by real
   cflib over ``sim://``: the real-time factor flat out (``speed=inf``; target >= 20x with >= 99 %
   of the packets delivered) and how closely ``speed=20`` is tracked when a 10 Hz client paces
   the simulation (each tick waits for the client's thread). Baseline, same run: the bare
   ``SimVehicle.advance`` loop.
2. ``groundstation sim`` in a child process, in real time, with a cflib client over UDP running
   the three 50 Hz blocks and 10 Hz setpoints: the child's CPU time per wall second. Target: < 10%
   of one core.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time

from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

import groundstation.sim as gsim
from groundstation.sim.vehicle import SimVehicle

BLOCKS = {
    "motors": [f"motor.m{i}" for i in range(1, 5)],
    "acc": ["acc.x", "acc.y", "acc.z"],
    "gyro": ["gyro.x", "gyro.y", "gyro.z"],
}
TARGET_FACTOR = 20.0
TARGET_CPU = 0.10


def _start_blocks(cf: Crazyflie, counter: list[int]) -> list[LogConfig]:
    confs = []
    for name, variables in BLOCKS.items():
        conf = LogConfig(name=name, period_in_ms=20)
        for var in variables:
            conf.add_variable(var)
        conf.data_received_cb.add_callback(lambda *_: counter.__setitem__(0, counter[0] + 1))
        cf.log.add_config(conf)
        conf.start()
        confs.append(conf)
    return confs


def _bare_factor(seconds: float = 2.0) -> float:
    vehicle = SimVehicle(seed=0)
    vehicle.commander_rpyt(roll=0.0, pitch=0.0, yawrate=0.0, thrust=0)
    vehicle.commander_rpyt(roll=0.0, pitch=0.0, yawrate=0.0, thrust=38000)
    t0 = time.perf_counter()
    vehicle.advance(seconds)
    return seconds / (time.perf_counter() - t0)


def _sim_factor(speed: str, wall_s: float) -> tuple[float, float]:
    """(real-time factor, fraction of expected log packets delivered) over ``wall_s``."""
    uri = f"sim://bench?speed={speed}"
    counter = [0]
    # as the flight runner does while flying: the paced simulation waits for this thread at
    # every deadline, and CPython's default 5 ms GIL switch interval is a whole tick at 20x
    sys.setswitchinterval(0.0005)
    with SyncCrazyflie(uri, cf=Crazyflie(rw_cache=None)) as scf:
        clock = gsim.instance(uri).clock
        confs = _start_blocks(scf.cf, counter)
        clock.sleep_until(clock.now() + 0.5)
        n0, s0, w0 = counter[0], clock.now(), time.perf_counter()
        k = 0
        while time.perf_counter() - w0 < wall_s:  # 10 Hz on absolute deadlines, as the runner
            scf.cf.commander.send_setpoint(0, 0, 0, 0)
            k += 1
            clock.sleep_until(s0 + 0.1 * k)
        n1, s1, w1 = counter[0], clock.now(), time.perf_counter()
        for conf in confs:
            conf.stop()
    return (s1 - s0) / (w1 - w0), (n1 - n0) / (3 * 50 * (s1 - s0))


def _cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _wait_for_probe(port: int, timeout_s: float = 30.0) -> None:
    """Wait until the server answers cflib's 0xFF scan probe."""
    deadline = time.monotonic() + timeout_s
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.settimeout(0.2)
        while time.monotonic() < deadline:
            try:
                s.sendto(b"\xff", ("127.0.0.1", port))
                if s.recv(64) == b"\xff":
                    return
            except OSError:
                time.sleep(0.1)
    raise RuntimeError(f"groundstation sim did not come up on port {port}")


def _udp_cpu(wall_s: float = 5.0) -> float:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    child = subprocess.Popen(
        [sys.executable, "-c", "from groundstation.cli import main; main()", "sim",
         "--port", str(port),
         "--duration", str(wall_s + 5)], stdout=subprocess.DEVNULL)
    try:
        _wait_for_probe(port)
        counter = [0]
        with SyncCrazyflie(f"udp://127.0.0.1:{port}", cf=Crazyflie(rw_cache=None)) as scf:
            _start_blocks(scf.cf, counter)
            time.sleep(0.5)
            c0, w0 = _cpu_seconds(child.pid), time.perf_counter()
            while time.perf_counter() - w0 < wall_s:
                scf.cf.commander.send_setpoint(0, 0, 0, 0)
                time.sleep(0.1)
            c1, w1 = _cpu_seconds(child.pid), time.perf_counter()
        return (c1 - c0) / (w1 - w0)
    finally:
        child.terminate()
        child.wait(timeout=10)


def main() -> int:
    gsim.install()
    bare = _bare_factor()
    flat, flat_delivered = _sim_factor("inf", 3.0)
    held, held_delivered = _sim_factor("20", 3.0)
    gsim.close_all()
    print(f"vehicle alone (baseline): {bare:6.1f}x real time")
    print(f"sim:// flat out, 3 blocks: {flat:6.1f}x real time = {flat / bare:.2f} of baseline, "
          f"{flat / TARGET_FACTOR:.2f} of the 20x target; {flat_delivered:.1%} packets delivered")
    print(f"sim:// at speed=20:        {held:6.1f}x real time = {held / TARGET_FACTOR:.2f} of "
          f"nominal, paced by a 10 Hz client (each 0.1 s tick waits for the client's thread); "
          f"{held_delivered:.1%} packets delivered")
    cpu = _udp_cpu()
    print(f"UDP server, real time, 3 blocks + 10 Hz setpoints: {cpu:.1%} of one core = "
          f"{cpu / TARGET_CPU:.2f} of the 10% budget")
    # The target is capacity: full physics plus three 50 Hz blocks at >= 20x (flat out), every
    # packet delivered; a paced run tracks its nominal speed to within the client's wake-ups.
    ok = (flat >= TARGET_FACTOR and flat_delivered >= 0.99 and held >= 0.85 * TARGET_FACTOR
          and held_delivered >= 0.99)
    return 0 if ok and cpu < TARGET_CPU else 1
