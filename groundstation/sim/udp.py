"""Simulated Crazyflies over UDP, for unmodified cflib scripts and the Crazyflie client.

The wire protocol is cflib's UDP driver (cflib >= 0.1.32, ``cflib/crtp/udpdriver.py``): one CRTP
packet per datagram, byte 0 the header, then 0-30 payload bytes; no handshake, no checksum. A
single ``0xFF`` byte is the scan probe (and a null packet) and is answered with ``0xFF``.

Vehicle ``i`` listens on ``port + i`` and runs in real time. It serves one client at a time:
the first address to send a non-null packet owns the link until it disconnects (a send to it
fails: its port is gone) or goes silent for :data:`CLIENT_SILENCE_S` of simulation time (the
firmware's link-down timeout); datagrams from any other address are ignored, counted in
``foreign`` and logged once, so nobody else on the machine can fly or listen to the vehicle.
Probes are answered whoever sends them (a scan still finds a vehicle in use). Empty, oversized
(> 31 bytes) and malformed datagrams are ignored; a client that goes silent leaves the vehicle to
its supervisor watchdog (and, after 1 s, to the firmware's link-down log reset), exactly as a
real one.

The server binds 127.0.0.1 by default. Any other address (``""`` and ``0.0.0.0`` included: every
interface) lets other machines fly the vehicle, so it needs ``allow_remote=True`` (the CLI's
``--allow-remote``) and logs a warning.
"""

from __future__ import annotations

import contextlib
import logging
import socket
import threading

from groundstation.errors import LinkError
from groundstation.sim.crtp import LINK_TIMEOUT_MS
from groundstation.sim.simulator import Simulator

__all__ = ["CLIENT_SILENCE_S", "MAX_DATAGRAM", "UdpServer", "is_loopback"]

logger = logging.getLogger(__name__)

MAX_DATAGRAM = 31  # header + 30 payload bytes
CLIENT_SILENCE_S = LINK_TIMEOUT_MS / 1000.0
"""Simulation seconds without a datagram after which the client's link is free for another."""
_LOOPBACK = ("127.", "localhost", "::1")
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
        self.client_seen_s = 0.0  # simulation time of the client's last datagram
        self.datagrams = 0
        self.ignored = 0
        self.foreign = 0  # datagrams from an address other than the client's
        self._warned = False
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
            self._release(client, why=f"send failed: {exc.strerror or exc}")

    def _release(self, client: tuple[str, int], *, why: str) -> None:
        if self.client == client:
            self.client = None
            logger.info("udp %d: client %s:%d gone (%s); the link is free", self.port,
                        *client, why)

    def _accept(self, addr: tuple[str, int]) -> bool:
        """Whether a packet from ``addr`` is the client's (taking a free link first)."""
        now = self.sim.published_s
        silent = now - self.client_seen_s > CLIENT_SILENCE_S
        if self.client is not None and self.client != addr and silent:
            self._release(self.client, why=f"silent for {now - self.client_seen_s:.1f} s")
        if self.client is None:
            self.client = addr
            logger.info("udp %d: serving %s:%d", self.port, *addr)
        if self.client != addr:
            self.foreign += 1
            if not self._warned:
                self._warned = True
                logger.warning("udp %d: ignoring datagrams from %s:%d while serving %s:%d "
                               "(counted, not logged again)", self.port, *addr, *self.client)
            return False
        self.client_seen_s = now
        return True

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
                if isinstance(exc, ConnectionRefusedError) and self.client is not None:
                    self._release(self.client, why="port unreachable")
                continue
            self.datagrams += 1
            if not data or len(data) > MAX_DATAGRAM:
                self.ignored += 1
                continue
            if data == _PROBE:  # scan probe / null packet: answer, do not take the link
                with contextlib.suppress(OSError):
                    self.sock.sendto(_PROBE, addr)
                continue
            if self._accept(addr):
                self.sim.submit(header=data[0], data=data[1:])

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2)
        self.sim.close()
        self.sock.close()


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine only (127.x.x.x, localhost, ::1)."""
    return host.lower().startswith(_LOOPBACK)


class UdpServer:
    """``count`` simulated Crazyflies on ``udp://host:port`` .. ``port + count - 1``.

    Binds 127.0.0.1 unless ``host`` says otherwise; an address other machines reach (``""``
    and ``0.0.0.0``: every interface) needs ``allow_remote=True`` and logs a warning. ``speed``
    is 1 (real time) for anything a person or cfclient talks to. Use as a context manager, or
    call :meth:`close`.
    """

    def __init__(self, *, host: str = "127.0.0.1", port: int = 19850, count: int = 1,
                 seed: int = 0, speed: float = 1.0, allow_remote: bool = False) -> None:
        host = host.strip() or "0.0.0.0"
        if not is_loopback(host):
            if not allow_remote:
                raise LinkError(f"--host {host} would let other machines fly the simulated "
                                "vehicle; pass --allow-remote to mean it, or serve 127.0.0.1")
            logger.warning("serving on %s: any machine that reaches it can fly the simulated "
                           "vehicle (one client at a time)", host)
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
