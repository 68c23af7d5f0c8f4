"""Connecting over ``udp://`` when datagrams are lost or slow, and the TOC cache.

Known truth: a proxy between cflib and :class:`~groundstation.sim.UdpServer` that drops chosen
requests or holds every answer. cflib's own UDP driver never resends, so one lost request is a
connection that waits for ever; the ground station's driver resends as cflib does on the radio,
and a connection that keeps answering is not cut by the silence timeout.
"""

from __future__ import annotations

import json
import queue
import socket
import threading
import time
from collections.abc import Callable

import pytest
from cflib.crtp.udpdriver import UdpDriver

from groundstation.errors import LinkError
from groundstation.flight.clock import MonotonicClock
from groundstation.flight.drivers import TOC_CACHE_ENV, install_drivers, resending_udp_driver
from groundstation.flight.link import open_link
from groundstation.sim import UdpServer
from tests.sim_crtp.helpers import free_udp_port


class Proxy:
    """``udp://127.0.0.1:port`` in front of ``target``: client datagram ``n`` (from 0, probes
    included) is dropped when ``drop(n)``; every answer waits ``delay_s`` first."""

    def __init__(self, target: tuple[str, int], *, drop: Callable[[int], bool] = lambda n: False,
                 delay_s: float = 0.0) -> None:
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind(("127.0.0.1", 0))
        self.back = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.back.connect(target)
        for s in (self.front, self.back):
            s.settimeout(0.1)
        self.drop, self.delay_s = drop, delay_s
        self.client: tuple[str, int] | None = None
        self.sent = self.dropped = 0
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=f, daemon=True) for f in (self._up, self._down)]
        for t in self._threads:
            t.start()

    @property
    def uri(self) -> str:
        return f"udp://127.0.0.1:{self.front.getsockname()[1]}"

    def _up(self) -> None:
        while not self._stop.is_set():
            try:
                data, self.client = self.front.recvfrom(64)
            except (TimeoutError, OSError):
                continue
            n, self.sent = self.sent, self.sent + 1
            if self.drop(n):
                self.dropped += 1
            else:
                self.back.send(data)

    def _down(self) -> None:
        while not self._stop.is_set():
            try:
                data = self.back.recv(64)
            except (TimeoutError, OSError):
                continue
            time.sleep(self.delay_s)
            if self.client is not None:
                self.front.sendto(data, self.client)

    def close(self) -> None:
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2)
        self.front.close()
        self.back.close()


@pytest.fixture(autouse=True)
def no_toc_cache(monkeypatch):
    """Every connect fetches the TOCs (130 requests to the simulator; 46 with them cached), so
    the drop and delay figures below do not depend on which tests ran before in this process;
    the cache tests name their own folder."""
    monkeypatch.setenv(TOC_CACHE_ENV, "off")


@pytest.fixture
def server():
    install_drivers()
    with UdpServer(port=free_udp_port(), seed=3) as srv:
        yield srv


def _connect(uri: str, **kw):
    return open_link(uri=uri, clock=MonotonicClock(), post=queue.SimpleQueue().put, **kw)


def _every_seventh_of_the_first_hundred(n: int) -> bool:
    return n < 100 and n % 7 == 3


def test_lost_requests_are_resent_and_the_connection_completes(server):
    proxy = Proxy(("127.0.0.1", server.endpoints[0].port), drop=_every_seventh_of_the_first_hundred)
    try:
        link = _connect(proxy.uri, timeout_s=10.0)
        try:
            assert isinstance(link.cf.link, resending_udp_driver())
            assert link.cf.link.needs_resending
            assert float(link.cf.param.get_value("pid_rate.roll_kp")) == pytest.approx(250.0)
        finally:
            link.close()
    finally:
        proxy.close()
    assert proxy.dropped >= 10  # the connection crossed every dropped request


def test_cflib_udp_driver_waits_for_ever_on_a_lost_request(server, monkeypatch):
    """The failure the resending driver removes: cflib's own UDP driver, the same losses."""
    import cflib.crtp

    monkeypatch.setattr(cflib.crtp, "CLASSES", [UdpDriver])
    proxy = Proxy(("127.0.0.1", server.endpoints[0].port), drop=_every_seventh_of_the_first_hundred)
    try:
        with pytest.raises(LinkError, match=r"^cannot connect to udp://.*: (no answer within 1 s|"
                                             r"the vehicle answers but .* after 3 s);"):
            _connect(proxy.uri, timeout_s=1.0, limit_s=3.0)
    finally:
        proxy.close()


# Closing mid-connect races cflib's parameter thread: it finds the link gone between its check
# and its send (AttributeError in cflib's thread), and cflib's send lock stays taken, which would
# hang the close for ever; the ground station's close is bounded (Link.close).
@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_a_slow_connection_that_keeps_answering_is_not_cut_by_the_silence_timeout(server):
    """Each answer 20 ms late: the connection takes several times ``timeout_s`` in all, with no
    silence as long as it; the whole connection is bounded by ``limit_s``, and giving up in the
    middle of it returns (the close cannot hang)."""
    proxy = Proxy(("127.0.0.1", server.endpoints[0].port), delay_s=0.02)
    try:
        t0 = time.monotonic()
        link = _connect(proxy.uri, timeout_s=1.0)
        took = time.monotonic() - t0
        link.close()
        assert took > 1.0  # longer than the silence allowed: the timeout is not the total
        with pytest.raises(LinkError, match=r"the vehicle answers but the connection was not "
                                            r"complete after 0.5 s; "):
            _connect(proxy.uri, timeout_s=1.0, limit_s=0.5)
    finally:
        proxy.close()


def test_the_tocs_are_cached_and_a_damaged_cache_file_is_fetched_again(server, tmp_path,
                                                                       monkeypatch):
    """First connect: both TOCs fetched and saved (one file per checksum). Second: far fewer
    datagrams (only the parameter values). Damaged files: fetched again, same values."""
    cache = tmp_path / "toc"
    monkeypatch.setenv(TOC_CACHE_ENV, str(cache))
    proxy = Proxy(("127.0.0.1", server.endpoints[0].port))
    sent, values = [], []
    try:
        for damage in (False, False, True):
            if damage:
                for f in cache.glob("*.json"):
                    f.write_text('{"log": [')
            before = proxy.sent
            link = _connect(proxy.uri)
            values.append(float(link.cf.param.get_value("pid_rate.roll_kp")))
            link.close()
            sent.append(proxy.sent - before)  # one server client: the proxy's socket
    finally:
        proxy.close()
    assert len(list(cache.glob("*.json"))) == 2  # the log and the parameter TOC
    assert sent[1] < 0.7 * sent[0] and sent[2] == pytest.approx(sent[0], rel=0.1), sent
    assert values == [250.0] * 3


def test_toc_cache_off(server, tmp_path, monkeypatch):
    cache = tmp_path / "toc"
    monkeypatch.setenv(TOC_CACHE_ENV, "off")
    link = _connect(server.uris[0])
    link.close()
    monkeypatch.setenv(TOC_CACHE_ENV, str(cache / "a-file"))
    cache.mkdir()
    (cache / "a-file").write_text("")  # not a folder: no cache, the connect goes on
    link = _connect(server.uris[0])
    link.close()
    assert not list(cache.glob("**/*.json"))


def test_a_cache_file_that_would_run_code_is_removed_before_cflib_reads_it(server, tmp_path,
                                                                         monkeypatch):
    """cflib's cache reader evaluates each element's ``__class__`` as Python: a crafted file
    under the right checksum name, whole or damaged after the crafted element, is removed,
    nothing runs, the TOC is fetched again."""
    cache, mark = tmp_path / "toc", tmp_path / "ran"
    monkeypatch.setenv(TOC_CACHE_ENV, str(cache))
    _connect(server.uris[0]).close()
    files = sorted(cache.glob("*.json"))
    assert len(files) == 2
    payload = f'exec("import pathlib; pathlib.Path({str(mark)!r}).touch()")'
    crafted = json.dumps({"pid_rate": {"roll_kp": {"__class__": payload, "ident": 0}}})
    # whole, and cut short after the crafted object (cflib's decoder runs it before it finds
    # that the file is damaged)
    for f, text in zip(files, (crafted, crafted[:-2]), strict=True):
        f.write_text(text)
    link = _connect(server.uris[0])
    value = float(link.cf.param.get_value("pid_rate.roll_kp"))
    link.close()
    assert not mark.exists() and value == 250.0
    assert sorted(cache.glob("*.json")) == files  # fetched again and saved again, plainly
    assert all("exec" not in f.read_text() for f in files)


# ------------------------------------------------------------ URIs refused before connecting
def _fly_error(uri: str, out) -> str:
    """``groundstation fly hover-check --uri URI``: exit 2, one error line and nothing else (no
    cflib text), no folder created; returns the line."""
    from click.testing import CliRunner

    from groundstation.cli import main

    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", uri, "--out", str(out),
                                    "--timeout", "2"])
    assert res.exit_code == 2, res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: cannot connect to "), res.output
    return lines[0]


@pytest.mark.parametrize(("uri", "says"), [
    ("tcp://foo", "unknown link URI scheme 'tcp://'"),
    ("tcp://foo:5000", "unknown link URI scheme 'tcp://'"),
    ("prrt://0", "unknown link URI scheme 'prrt://'"),
    ("udp://127.0.0.1", "udp://HOST:PORT"),
    ("udp://:19850", "udp://HOST:PORT"),
    ("udp://127.0.0.1:70000", "udp://HOST:PORT"),
    ("udp://127.0.0.1:port", "udp://HOST:PORT"),
    ("sim://x", "'x' is not a number"),
    ("sim://x?speed=inf", "'x' is not a number"),
    ("radio://0/126/2M/E7E7E7E7E7", "radio://DONGLE/CHANNEL/RATE/ADDRESS"),
    ("radio://0/80/3M/E7E7E7E7E7", "radio://DONGLE/CHANNEL/RATE/ADDRESS"),
    ("radio://0/80/2M/XYZ", "radio://DONGLE/CHANNEL/RATE/ADDRESS"),
    ("usb://first", "usb://N"),
])
def test_unsupported_and_malformed_uris_are_refused_before_connecting(tmp_path, uri, says):
    line = _fly_error(uri, tmp_path / "s")
    assert says in line and "e.g." in line
    assert "NoneType" not in line and "Crazyflie is on" not in line
    assert not (tmp_path / "s").exists()


def test_a_refused_udp_connection_points_at_the_simulator_not_the_radio(tmp_path):
    port = free_udp_port()  # nothing listens there: the datagrams are refused
    line = _fly_error(f"udp://127.0.0.1:{port}", tmp_path / "s")
    assert f"listening on 127.0.0.1:{port}" in line and f"groundstation sim --port {port}" in line
    assert "channel" not in line and "groundstation scan" not in line


@pytest.mark.parametrize("why", ["Couldn't load link driver: [Errno -2] Name or service not "
                                 "known", "[Errno -3] Temporary failure in name resolution"])
def test_a_udp_host_that_does_not_resolve_says_so(why):
    """(cflib's reasons as given; no lookup here: tests use no network.)"""
    from groundstation.flight.uri import connect_advice

    advice = connect_advice(why, uri="udp://nonexistent.invalid:19850")
    assert advice.startswith("the host name 'nonexistent.invalid' does not resolve")
