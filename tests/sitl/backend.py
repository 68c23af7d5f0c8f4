"""The SITL backend of the flight tests: the real Crazyflie firmware (``make sitl``) with our
physics, served in process on a free loopback port per vehicle; skipped with the reason when the
firmware is not built."""

from __future__ import annotations

import socket
import time

import pytest

from groundstation.errors import GroundStationError
from groundstation.flight.link import install_drivers
from groundstation.sim.sitl import SitlVehicle, find_firmware

_vehicles: dict[str, SitlVehicle] = {}


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def firmware_or_skip():
    """The ``cf2`` path, or skip the test naming why (and how to build it)."""
    try:
        return find_firmware()
    except GroundStationError as exc:
        pytest.skip(str(exc))


def start_vehicle(*, seed: int = 0) -> SitlVehicle:
    """A calibrated firmware instance on a fresh port (closed by :func:`close_all`); cflib's
    drivers are ready for its URI."""
    install_drivers()
    v = SitlVehicle(firmware=firmware_or_skip(), port=free_udp_port(), seed=seed)
    _vehicles[v.uri] = v
    v.wait_ready()
    return v


def vehicle(uri: str) -> SitlVehicle:
    return _vehicles[uri]


def close_all() -> None:
    """Stop every firmware process started here; none may survive."""
    vs = list(_vehicles.values())
    _vehicles.clear()
    for v in vs:
        v.close()
    assert all(not v.alive for v in vs)


def wait_for_stop(uri: str, timeout_s: float = 10.0) -> SitlVehicle:
    """The vehicle once the real firmware's motor commands are all zero and it rests on the
    ground (the physics' view of the firmware's output)."""
    v = _vehicles[uri]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if not any(v.peer.pwm) and v.peer.body.on_ground:
            return v
        time.sleep(0.02)
    raise AssertionError(f"SITL vehicle not stopped: motors {v.peer.pwm}, "
                         f"z {v.peer.body.z:.2f} m")
