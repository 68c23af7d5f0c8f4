"""Simulated Crazyflies over UDP, for unmodified cflib scripts and the Crazyflie client.

The wire protocol is cflib's UDP driver (cflib >= 0.1.32, ``cflib/crtp/udpdriver.py``): one CRTP
packet per datagram, byte 0 the header, then 0-30 payload bytes; no handshake, no checksum. A
single ``0xFF`` byte is the scan probe (and a null packet) and is answered with ``0xFF``.

Vehicle ``i`` listens on ``port + i`` and runs in real time. It answers whoever sent it the last
non-null packet, like a radio that has one link. Empty, oversized (> 31 bytes) and malformed
datagrams are ignored; a client that goes silent leaves the vehicle to its supervisor watchdog
(and, after 1 s, to the firmware's link-down log reset), exactly as a real one.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading

from groundstation.errors import LinkError
from groundstation.sim.crtp import LINK_TIMEOUT_MS
from groundstation.sim.simulator import Simulator

__all__ = ["MAX_DATAGRAM", "UdpServer"]

logger = logging.getLogger(__name__)

MAX_DATAGRAM = 31  # header + 30 payload bytes
_PROBE = b"\xff"


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
        self.client: tuple[str, int] | None = None
        self.datagrams = 0
        self.ignored = 0
        self.sim = Simulator(address=f"udp:{port}", speed=speed, seed=seed, sink=self._send,
                             linger=False, link_timeout_ms=LINK_TIMEOUT_MS)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._serve, name=f"sim-udp-{port}", daemon=True)
        self._thread.start()

    def _send(self, header: int, payload: bytes) -> None:
        client = self.client
        if client is None:
            return
        try:
            self.sock.sendto(bytes([header]) + payload, client)
        except OSError as exc:  # e.g. the client's port is gone (ICMP unreachable)
            logger.debug("udp %d: send to %s failed: %s", self.port, client, exc)

    def _serve(self) -> None:
        while not self._stop.is_set():
            try:
                data, addr = self.sock.recvfrom(2048)
            except TimeoutError:
                continue
            except OSError as exc:  # closed, or an ICMP error reported on the socket
                if self._stop.is_set():
                    break
                logger.debug("udp %d: receive error %s", self.port, exc)
                continue
            self.datagrams += 1
            if not data or len(data) > MAX_DATAGRAM:
                self.ignored += 1
                continue
            if data == _PROBE:  # scan probe / null packet: answer, do not take the link
                with contextlib.suppress(OSError):
                    self.sock.sendto(_PROBE, addr)
                continue
            self.client = addr
            self.sim.submit(header=data[0], data=data[1:])

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.sim.close()
        self.sock.close()


class UdpServer:
    """``count`` simulated Crazyflies on ``udp://host:port`` .. ``port + count - 1``.

    Binds 127.0.0.1 unless ``host`` says otherwise. ``speed`` is 1 (real time) for anything a
    person or cfclient talks to. Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, *, host: str = "127.0.0.1", port: int = 19850, count: int = 1,
                 seed: int = 0, speed: float = 1.0) -> None:
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
