"""Who may talk to a served vehicle: cflib's UDP link, one client at a time, on a checked host.

Both servers of ``groundstation sim`` use this: the simulator (:mod:`groundstation.sim.udp`,
silence measured in simulation time) and the relay to the real firmware
(:mod:`groundstation.sim.sitl`, wall-clock time). The wire protocol is cflib's UDP driver: one
CRTP packet per datagram (header and 0-30 payload bytes); a single ``0xFF`` byte is the scan
probe (and a null packet), answered with ``0xFF`` whoever sends it, so a scan still finds a
vehicle in use.

:class:`ClientLink` gives the link to the first address that sends a non-null packet and keeps
it until that client disconnects or goes silent for :data:`CLIENT_SILENCE_S` by the server's
clock (the firmware's link-down timeout). cflib sends nothing when it closes, so a disconnect is
seen when a packet sent to the client comes back as ICMP "port unreachable": the socket gets
``IP_RECVERR`` (Linux) and its error queue names the address that bounced; a bounce from anyone
else (a scanner that closed before the probe's answer) leaves the link alone. A datagram from
another address first sends the client a null packet: a client that closed and reconnects from
a new port (cflib's UDP driver never resends, so its first packet must not be lost) gets the
link at once, on loopback. Without ``IP_RECVERR`` (other systems) only the silence frees the
link. Datagrams of any other address are ignored, counted in ``foreign`` and logged once, so
nobody else on the machine can fly the vehicle or listen to it (the client receives a null
packet for each, which cflib ignores).

:func:`check_host` is the bind rule: 127.0.0.1 by default; any address other machines reach
(``""`` and ``0.0.0.0`` included: every interface) needs ``allow_remote`` (the CLI's
``--allow-remote``) and logs a warning.
"""

from __future__ import annotations

import contextlib
import ipaddress
import logging
import os
import select
import socket
import sys
import threading
from collections.abc import Callable

from groundstation.errors import LinkError
from groundstation.sim.crtp import LINK_TIMEOUT_MS

__all__ = ["CLIENT_SILENCE_S", "MAX_DATAGRAM", "PROBE", "ClientLink", "check_host",
           "is_loopback"]

logger = logging.getLogger(__name__)

MAX_DATAGRAM = 31  # header + 30 payload bytes
PROBE = b"\xff"
CLIENT_SILENCE_S = LINK_TIMEOUT_MS / 1000.0
"""Seconds (of the server's clock) without a datagram after which the link is free for another."""
_IP_RECVERR = getattr(socket, "IP_RECVERR", 11)  # Linux <linux/in.h>; Python 3.11 lacks the name
_MAX_DRAIN = 64  # error-queue entries read per call (each is one bounced datagram)

Address = tuple[str, int]


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine only (127.0.0.0/8, ``::1`` or ``localhost``)."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host.lower() == "localhost"


def check_host(host: str, *, allow_remote: bool, what: str = "the simulated vehicle",
               warn: bool = True) -> str:
    """``host`` to bind (blank: ``0.0.0.0``), or :class:`LinkError` (one line) when other
    machines could reach it without ``allow_remote``; with it, a warning is logged (``warn``)."""
    host = host.strip() or "0.0.0.0"
    if not is_loopback(host):
        if not allow_remote:
            raise LinkError(f"--host {host} would let other machines fly {what}; "
                            "pass --allow-remote to mean it, or serve 127.0.0.1")
        if warn:
            logger.warning("serving on %s: any machine that reaches it can fly %s "
                           "(one client at a time)", host, what)
    return host


class ClientLink:
    """One bound UDP socket serving one client at a time.

    ``name`` prefixes the log lines (e.g. ``udp 19850``); ``clock`` gives the seconds the
    silence is measured in (simulation time for the simulator, :func:`time.monotonic` for the
    firmware relay). :meth:`receive` returns the client's next packet; :meth:`send` sends one to
    the client (any thread). Counters: ``datagrams`` received, ``ignored`` (empty, oversized),
    ``foreign`` (from an address other than the client's).
    """

    def __init__(self, sock: socket.socket, *, name: str, clock: Callable[[], float],
                 silence_s: float = CLIENT_SILENCE_S) -> None:
        self.sock = sock
        self.name = name
        self.clock = clock
        self.silence_s = silence_s
        self.client: Address | None = None
        self.client_seen_s = 0.0  # the clock at the client's last datagram
        self.datagrams = 0
        self.ignored = 0
        self.foreign = 0
        self._warned = False
        self._lock = threading.RLock()  # held by accept() while a bounce releases
        self._drain_lock = threading.Lock()
        self._errors: select.poll | None = None
        if sys.platform.startswith("linux") and sock.family == socket.AF_INET:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.IPPROTO_IP, _IP_RECVERR, 1)
                self._errors = select.poll()
                self._errors.register(sock, select.POLLERR)

    def receive(self) -> bytes | None:
        """The client's next packet (header first), or ``None`` when the socket's timeout passed
        or the datagram was not the client's (probe answered, junk or foreign ignored)."""
        try:
            data, addr = self.sock.recvfrom(2048)
        except TimeoutError:
            return None
        except OSError as exc:  # closed, or an ICMP error reported on the socket
            logger.debug("%s: receive error %s", self.name, exc)
            self._drain_errors()
            return None
        self.datagrams += 1
        if not data or len(data) > MAX_DATAGRAM:
            self.ignored += 1
            return None
        if data == PROBE:  # scan probe / null packet: answer, do not take the link
            with contextlib.suppress(OSError):
                self.sock.sendto(PROBE, addr)
            return None
        return data if self.accept(addr) else None

    def accept(self, addr: Address) -> bool:
        """Whether a packet from ``addr`` is the client's (taking a free link first)."""
        with self._lock:
            now = self.clock()
            client = self.client
            if client is not None and client != addr:
                if now - self.client_seen_s > self.silence_s:
                    self._release_locked(client, why=f"silent for {now - self.client_seen_s:.1f} s")
                else:
                    self._ask(client)
                client = self.client
            if client is None:
                self.client = client = addr
                logger.info("%s: serving %s:%d", self.name, *addr)
            if client != addr:
                self.foreign += 1
                if not self._warned:
                    self._warned = True
                    logger.warning("%s: ignoring datagrams from %s:%d while serving %s:%d "
                                   "(counted, not logged again)", self.name, *addr, *client)
                return False
            self.client_seen_s = now
            return True

    def send(self, data: bytes) -> bool:
        """Send ``data`` to the client; False when there is none, it is gone or the send failed.

        A send fails when an earlier datagram's bounce is pending on the socket: the error queue
        is read (freeing the link if the client bounced) and, the client still there, the send
        is made once more.
        """
        for attempt in range(2):
            client = self.client
            if client is None:
                return False
            try:
                self.sock.sendto(data, client)
                return True
            except OSError as exc:
                logger.debug("%s: send to %s:%d failed: %s", self.name, *client, exc)
                if attempt == 0:
                    self._drain_errors()
        return False

    def _ask(self, client: Address) -> None:
        """Send the client a null packet: if its port is gone (a client that closed and
        reconnects from a new port, and cflib does not resend its first packet), the bounce
        frees the link now; on loopback it is back before ``sendto`` returns."""
        if self._errors is None:
            return
        with contextlib.suppress(OSError):
            self.sock.sendto(PROBE, client)
        self._drain_errors()

    def release(self, client: Address, *, why: str) -> None:
        """Free the link if ``client`` still holds it."""
        with self._lock:
            self._release_locked(client, why=why)

    def _release_locked(self, client: Address, *, why: str) -> None:
        if self.client == client:
            self.client = None
            logger.info("%s: client %s:%d gone (%s); the link is free", self.name, *client, why)

    def _drain_errors(self) -> None:
        """Read the socket's error queue (``IP_RECVERR``): each entry is a datagram that bounced,
        with the address it was sent to; a bounce from the client frees the link."""
        if self._errors is None:
            return
        bounced: list[tuple[Address, int]] = []
        with self._drain_lock:  # never held while taking self._lock (accept() holds that)
            for _ in range(_MAX_DRAIN):
                with contextlib.suppress(OSError):  # clear the pending error: POLLERR then
                    self.sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR)  # means a queued one
                if not self._errors.poll(0):
                    break
                try:
                    _, ancdata, _, addr = self.sock.recvmsg(0, 512, socket.MSG_ERRQUEUE)
                except OSError:
                    break
                code = int.from_bytes(ancdata[0][2][:4], sys.byteorder) if ancdata else 0
                bounced.append((addr, code))
        for addr, code in bounced:
            if addr == self.client:
                self.release(addr, why=os.strerror(code).lower() if code else "bounced")
