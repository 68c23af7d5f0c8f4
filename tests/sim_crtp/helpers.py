"""Helpers for flying the simulated Crazyflie through real cflib."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.log import LogConfig
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie

from groundstation.flight.clock import Clock
from groundstation.flight.drivers import toc_cache_dir

__all__ = ["BLOCKS", "Recorder", "connect", "fly"]

# The thesis' three 50 Hz blocks: motors (4 x uint16), accelerometer and gyro (3 x float each).
BLOCKS = {
    "motors": [f"motor.m{i}" for i in range(1, 5)],
    "acc": ["acc.x", "acc.y", "acc.z"],
    "gyro": ["gyro.x", "gyro.y", "gyro.z"],
}


@contextmanager
def connect(uri: str, *, toc_cache: bool = False) -> Iterator[SyncCrazyflie]:
    """An open, fully connected link (all parameters read once). The TOCs are fetched from
    the vehicle unless ``toc_cache``: then cflib keeps them in the run's TOC cache, as the
    ground station does (a second connect to the real firmware in the loop reads only the
    parameter values: 0.8 s instead of 1.9 s), for tests whose subject is not the TOC."""
    cache = toc_cache_dir() if toc_cache else None
    cf = Crazyflie(rw_cache=None if cache is None else str(cache))
    fully = threading.Event()
    cf.fully_connected.add_callback(lambda uri: fully.set())
    with SyncCrazyflie(uri, cf=cf) as scf:
        assert fully.wait(10), f"{uri}: not fully connected within 10 s"
        yield scf


class Recorder:
    """Log blocks started on ``cf``; ``rows(name)`` -> (timestamps ms (n,), values (n, k))."""

    def __init__(self, cf: Crazyflie, *, blocks: dict[str, list[str]], period_ms: int = 20):
        self._lock = threading.Lock()
        self._data: dict[str, list[tuple[int, list[float]]]] = {n: [] for n in blocks}
        self.configs = []
        for name, variables in blocks.items():
            conf = LogConfig(name=name, period_in_ms=period_ms)
            for var in variables:
                conf.add_variable(var)
            conf.data_received_cb.add_callback(self._on_data)
            cf.log.add_config(conf)
            self.configs.append(conf)
        for conf in self.configs:
            conf.start()
        self._names = blocks

    def _on_data(self, timestamp: int, data: dict, conf: LogConfig) -> None:
        with self._lock:
            self._data[conf.name].append((timestamp, [data[v] for v in self._names[conf.name]]))

    def rows(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        with self._lock:
            rows = list(self._data[name])
        t = np.array([r[0] for r in rows], dtype=np.int64)
        v = np.array([r[1] for r in rows], dtype=float).reshape(len(rows), len(self._names[name]))
        return t, v


def fly(cf: Crazyflie, clock: Clock, segments: list[tuple[float, float, float, float, int]],
        rate_hz: float = 10.0) -> None:
    """Send RPYT setpoints at ``rate_hz`` on the simulation clock: segments of
    (duration s, roll deg, pitch deg, yaw rate deg/s, thrust)."""
    t = clock.now()
    for duration, roll, pitch, yawrate, thrust in segments:
        end = t + duration
        while t < end:
            cf.commander.send_setpoint(roll, pitch, yawrate, thrust)
            t += 1.0 / rate_hz
            clock.sleep_until(t)


def free_udp_port() -> int:
    """A UDP port on 127.0.0.1 that nothing holds right now (for a test's simulator)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
