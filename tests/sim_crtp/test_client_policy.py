"""The client policy both UDP servers share (the simulator and the firmware relay): one client
at a time on the server's clock, others counted and logged once, probes answered to anyone, a
closed client frees the link when a packet to it bounces, and the host rule. Real sockets on
127.0.0.1; the silence is measured by a clock the test moves."""

from __future__ import annotations

import logging
import select
import socket
import sys

import pytest

from groundstation.errors import LinkError
from groundstation.sim.client_policy import CLIENT_SILENCE_S, ClientLink, check_host

PACKET = b"\xfc" + b"hello"  # link service, echo channel
linux = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="IP_RECVERR is Linux's")


@pytest.fixture
def loopback():
    """(server socket, client a, client b), all bound on 127.0.0.1."""
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(3)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
        s.settimeout(10.0)  # datagrams arrive at once on loopback; generous on a loaded host
    yield socks
    for s in socks:
        s.close()


def test_the_link_is_the_first_senders_until_silent_by_the_given_clock(loopback, caplog):
    server, a, b = loopback
    now = [100.0]  # a clock the test moves: silence is measured by it, not the wall clock
    link = ClientLink(server, name="test", clock=lambda: now[0])
    to = server.getsockname()
    a.sendto(PACKET, to)
    assert link.receive() == PACKET and link.client == a.getsockname()
    for _ in range(3):
        b.sendto(PACKET, to)
        assert link.receive() is None
    assert link.foreign == 3 and link.client == a.getsockname()
    now[0] += CLIENT_SILENCE_S * 0.9
    a.sendto(PACKET, to)  # still the client's: it keeps the link alive
    assert link.receive() == PACKET
    now[0] += CLIENT_SILENCE_S * 0.9
    b.sendto(PACKET, to)
    assert link.receive() is None and link.foreign == 4
    now[0] += CLIENT_SILENCE_S  # a has been silent for longer than CLIENT_SILENCE_S
    b.sendto(PACKET, to)
    assert link.receive() == PACKET and link.client == b.getsockname()
    assert link.datagrams == 7
    warnings = [r for r in caplog.records if "ignoring datagrams" in r.getMessage()]
    assert len(warnings) == 1  # logged once, counted after


def test_probe_answered_to_anyone_and_junk_ignored(loopback):
    server, a, b = loopback
    link = ClientLink(server, name="test", clock=lambda: 0.0)
    to = server.getsockname()
    a.sendto(PACKET, to)
    assert link.receive() == PACKET
    b.sendto(b"\xff", to)  # cflib's scan probe from another address: answered, link kept
    assert link.receive() is None and b.recv(64) == b"\xff"
    for junk in (b"", bytes(32)):
        a.sendto(junk, to)
        assert link.receive() is None
    assert (link.client, link.foreign, link.ignored) == (a.getsockname(), 0, 2)
    assert link.send(b"\xfcreply") and a.recv(64) == b"\xfcreply"


def _bounced(server: socket.socket) -> None:
    """Wait (generously) until an ICMP error is pending on ``server``."""
    poller = select.poll()
    poller.register(server, select.POLLERR)
    assert poller.poll(10_000), "no ICMP error came back"


@linux
def test_a_client_that_reconnects_from_a_new_port_gets_the_link_at_its_first_packet(loopback,
                                                                                   caplog):
    """cflib sends nothing when it closes and never resends: a foreign datagram asks the client
    (a null packet); a closed one bounces and the newcomer's packet is taken, not lost."""
    caplog.set_level(logging.INFO, logger="groundstation.sim.client_policy")
    server, a, b = loopback
    link = ClientLink(server, name="test", clock=lambda: 0.0)  # no silence: only the bounce
    to = server.getsockname()
    a.sendto(PACKET, to)
    assert link.receive() == PACKET
    b.sendto(PACKET, to)  # a is there: b is foreign, a got asked
    assert link.receive() is None and link.foreign == 1 and a.recv(64) == b"\xff"
    gone = a.getsockname()
    a.close()
    b.sendto(PACKET, to)
    assert link.receive() == PACKET and link.client == b.getsockname() and link.foreign == 1
    assert any(f"client 127.0.0.1:{gone[1]} gone (connection refused)" in r.getMessage()
               for r in caplog.records)


@linux
def test_a_client_whose_port_is_gone_is_released_when_a_packet_to_it_bounces(loopback):
    server, a, _ = loopback
    link = ClientLink(server, name="test", clock=lambda: 0.0)
    a.sendto(PACKET, server.getsockname())
    assert link.receive() == PACKET
    a.close()
    assert link.send(b"\xfcto a")  # goes out, and comes back as ICMP port unreachable
    _bounced(server)
    assert link.client is not None
    assert link.receive() is None  # the socket reports the error; the queue names a
    assert link.client is None and not link.send(b"\xfc")


@linux
def test_a_bounce_from_another_address_keeps_the_link_and_the_send(loopback):
    """A scanner that closed before the probe's answer: its bounce must not cost the client
    its link, nor the packet whose send reported the bounce."""
    server, a, b = loopback
    link = ClientLink(server, name="test", clock=lambda: 0.0)
    to = server.getsockname()
    a.sendto(PACKET, to)
    assert link.receive() == PACKET
    b.sendto(b"\xff", to)
    b.close()
    assert link.receive() is None  # the probe, answered to a closed port
    _bounced(server)
    assert link.send(b"\xfcreply")  # the pending error fails the first try; sent again
    assert a.recv(64) == b"\xfcreply" and link.client == a.getsockname()
    link.release(("127.0.0.1", 1), why="not the client")  # only the holder is released
    assert link.client == a.getsockname()


@pytest.mark.parametrize("host", ["", " ", "0.0.0.0", "192.0.2.1", "localhost.example.com",
                                  "127.0.0.1.example.com"])
def test_a_host_others_reach_needs_allow_remote_and_warns(host, caplog):
    with pytest.raises(LinkError, match=r"would let other machines fly .*--allow-remote"):
        check_host(host, allow_remote=False)
    assert check_host(host, allow_remote=True) == (host.strip() or "0.0.0.0")
    assert any("any machine that reaches it" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("host", ["127.0.0.1", "127.0.0.2", "localhost", "::1"])
def test_loopback_needs_nothing(host, caplog):
    assert check_host(host, allow_remote=False) == host
    assert not caplog.records
