"""Simulated Crazyflies over UDP, for unmodified cflib scripts and the Crazyflie client.

The wire protocol is cflib's UDP driver (cflib >= 0.1.32, ``cflib/crtp/udpdriver.py``): one CRTP
packet per datagram, byte 0 the header, then 0-30 payload bytes; no handshake, no checksum. A
single ``0xFF`` byte is the scan probe (and a null packet) and is answered with ``0xFF``.

Vehicle ``i`` listens on ``port + i`` and runs in real time. Who may talk to it is
:mod:`groundstation.sim.client_policy`, shared with the relay to the real firmware
(``groundstation sim --firmware``): one client at a time, the first address to send a non-null
packet, until it disconnects (a packet sent to it bounces: its port is gone) or goes silent for
:data:`CLIENT_SILENCE_S` of simulation time (the firmware's link-down timeout); datagrams from
any other address are ignored, counted in ``foreign`` and logged once, so nobody else on the
machine can fly or listen to the vehicle. Probes are answered whoever sends them (a scan still
finds a vehicle in use). Empty, oversized (> 31 bytes) and malformed datagrams are ignored; a
client that goes silent leaves the vehicle to its supervisor watchdog (and, after 1 s, to the
firmware's link-down log reset), exactly as a real one.

The server binds 127.0.0.1 by default. Any other address (``""`` and ``0.0.0.0`` included: every
interface) lets other machines fly the vehicle, so it needs ``allow_remote=True`` (the CLI's
``--allow-remote``) and logs a warning.
"""

from __future__ import annotations

import socket
import threading

from groundstation.errors import LinkError
from groundstation.sim.client_policy import (
    CLIENT_SILENCE_S,
    MAX_DATAGRAM,
    ClientLink,
    check_host,
    is_loopback,
)
from groundstation.sim.crtp import LINK_TIMEOUT_MS
from groundstation.sim.simulator import Simulator

__all__ = ["CLIENT_SILENCE_S", "MAX_DATAGRAM", "UdpServer", "is_loopback"]


class _Endpoint:
    """One vehicle on one UDP socket: a receiver thread feeding a :class:`Simulator`."""

    def __init__(self, *, host: str, port: int, seed: int, speed: float) -> None:
        self.port = port
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host, port))
        except OSError as exc:
            self.sock.close()
            raise LinkError(f"cannot listen on udp://{host}:{port} ({exc.strerror}); "
                            "choose another --port or --host") from None
        self.sock.settimeout(0.2)
        # The silence that frees the link is measured in simulation time.
        self.link = ClientLink(self.sock, name=f"udp {port}", clock=lambda: self.sim.published_s)
        self.sim = Simulator(address=f"udp:{port}", speed=speed, seed=seed, sink=self._send,
                             linger=False, link_timeout_ms=LINK_TIMEOUT_MS)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name=f"sim-udp-{port}", daemon=True)
        self._thread.start()

    # The link's state and counters, as the endpoint's (tests and the fuzz harness read them).
    @property
    def client(self) -> tuple[str, int] | None:
        return self.link.client

    @property
    def client_seen_s(self) -> float:
        """Simulation time of the client's last datagram."""
        return self.link.client_seen_s

    @property
    def datagrams(self) -> int:
        return self.link.datagrams

    @property
    def ignored(self) -> int:
        return self.link.ignored

    @property
    def foreign(self) -> int:
        """Datagrams from an address other than the client's."""
        return self.link.foreign

    def _send(self, header: int, payload: bytes) -> None:
        self.link.send(bytes([header]) + payload)

    def _serve(self) -> None:
        while not self._stop.is_set():
            data = self.link.receive()
            if data is not None:
                self.sim.submit(header=data[0], data=data[1:])

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.sim.close()
        self.sock.close()


class UdpServer:
    """``count`` simulated Crazyflies on ``udp://host:port`` .. ``port + count - 1``.

    Binds 127.0.0.1 unless ``host`` says otherwise; an address other machines reach (``""``
    and ``0.0.0.0``: every interface) needs ``allow_remote=True`` and logs a warning. ``speed``
    is 1 (real time) for anything a person or cfclient talks to. Use as a context manager, or
    call :meth:`close`.
    """

    def __init__(self, *, host: str = "127.0.0.1", port: int = 19850, count: int = 1,
                 seed: int = 0, speed: float = 1.0, allow_remote: bool = False) -> None:
        host = check_host(host, allow_remote=allow_remote)
        if not 1 <= count <= 10:
            raise LinkError(f"--count {count} is out of range; serve 1 to 10 vehicles")
        if not 1 <= port <= 65535 - count + 1:
            raise LinkError(f"--port {port} is out of range; use 1..{65536 - count}")
        self.host = host
        self.endpoints: list[_Endpoint] = []
        try:
            for i in range(count):
                self.endpoints.append(
                    _Endpoint(host=host, port=port + i, seed=seed + i, speed=speed))
        except BaseException:
            self.close()
            raise

    @property
    def uris(self) -> list[str]:
        """The cflib URIs of the vehicles, e.g. ``udp://127.0.0.1:19850``."""
        return [f"udp://{self.host}:{e.port}" for e in self.endpoints]

    @property
    def simulators(self) -> list[Simulator]:
        """The simulations, in port order (for tests: ``.vehicle``, faults)."""
        return [e.sim for e in self.endpoints]

    def close(self) -> None:
        """Stop every vehicle and its threads and release the ports."""
        for endpoint in self.endpoints:
            endpoint.close()
        self.endpoints = []

    def __enter__(self) -> UdpServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
