"""The cflib connection of a flight: connect, TOC, log blocks started, setpoints, metadata.

:func:`open_link` connects to a Crazyflie (``radio://``, ``usb://``, ``udp://`` or the simulator's
``sim://``; :mod:`groundstation.flight.uri`) with a timeout and returns a :class:`Link`. Everything
cflib calls back from its own threads (log packets, console text, link quality and latency, link
loss) is turned into a tuple and handed to ``post`` (the flight runner's queue), stamped with the
flight clock:

=====================================================  =========================================
``("log", block, t, fw_ms, values)``                   one log packet; ``values`` in block order
``("console", t, text)``                               console text as it arrives (not by line)
``("link", t, quality_pct, latency_ms)``               one of the two is NaN
``("lost", t, message)``                               the link was lost (cflib connection_lost)
``("log_error", t, message)``                          cflib refused or failed a log block
``("late_close", t, message)``                         cflib did not close within CLOSE_TIMEOUT_S
=====================================================  =========================================

``t`` is ``clock.now()`` in seconds. The blocks logged and their checks against the TOC are
:mod:`groundstation.flight.blocks` (re-exported here).
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import socket
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Literal

from groundstation.dongle import check_dongle, radio_metadata
from groundstation.errors import LinkError
from groundstation.flight.blocks import (
    ATTITUDE_BLOCK,
    BATTERY_BLOCK,
    BLOCK_PERIOD_S,
    FLIGHT_BLOCKS,
    LOG_MAX_BYTES,
    BlockPlan,
    plan_blocks,
)
from groundstation.flight.clock import Clock
from groundstation.flight.drivers import install_drivers, toc_cache_dir
from groundstation.flight.params import typed_value
from groundstation.flight.thread_errors import log_cflib_thread_errors
from groundstation.flight.uri import DEFAULT_URI, URI_SCHEMES, check_uri, connect_advice

__all__ = [
    "ATTITUDE_BLOCK",
    "BATTERY_BLOCK",
    "BLOCK_PERIOD_S",
    "CLOSE_TIMEOUT_S",
    "CONNECT_LIMIT_S",
    "DEFAULT_URI",
    "FLIGHT_BLOCKS",
    "LOG_MAX_BYTES",
    "SEND_TIMEOUT_S",
    "STOP_REPEATS",
    "URI_SCHEMES",
    "BlockPlan",
    "Link",
    "check_uri",
    "install_drivers",
    "open_link",
    "plan_blocks",
]

log = logging.getLogger(__name__)

CONNECT_LIMIT_S = 120.0
"""Longest a connection may take in all while the vehicle keeps answering (seconds)."""
STOP_REPEATS = 5
STOP_SPACING_S = 0.02
"""The stop setpoint is sent :data:`STOP_REPEATS` times this far apart (flight clock, s)."""
DRAIN_TIMEOUT_S = 0.5
"""Longest wait (wall s) for the link driver to send what is queued before the link closes."""
SEND_TIMEOUT_S = 1.5
"""Longest wait (wall s) for cflib to take a setpoint or close the link. Longer is a stuck link:
with the Crazyradio unplugged cflib's radio driver stops taking packets, blocks the sender for 2 s
and then deadlocks in its link-error path (the sender holds ``Crazyflie._send_lock`` while the
error handler joins the ping thread, which waits for that lock), so these calls never return."""
CLOSE_TIMEOUT_S = 10.0
"""Longest wait (wall s) for cflib to close the link. Closing joins cflib's threads (the UDP
driver's receiver polls its socket once a second, the packet handler is joined for up to 1 s),
so it takes 1-2 s on an idle host and longer on a busy one; it comes after the stop setpoint was
delivered, so one that does not return is a warning in the session, not a lost flight."""

_PLATFORM_PORT, _VERSION_CHANNEL, _VERSION_GET_FIRMWARE = 13, 1, 1

Post = Callable[[tuple], None]


class _Caller:
    """One daemon thread making the cflib calls that can hang, so the caller can give up."""

    def __init__(self, name: str) -> None:
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        threading.Thread(target=self._run, name=name, daemon=True).start()

    def _run(self) -> None:
        while True:
            fn, done, error = self._jobs.get()
            try:
                fn()
            except BaseException as exc:  # handed to the caller
                error.append(exc)
            done.set()

    def call(self, fn: Callable[[], Any], *, timeout_s: float) -> bool:
        """Run ``fn`` on the thread; ``False`` if it did not return within ``timeout_s``
        (it stays stuck there); its exception is raised here."""
        done, error = threading.Event(), []
        self._jobs.put((fn, done, error))
        if not done.wait(timeout_s):
            return False
        if error:
            raise error[0]
        return True


class Link:
    """An open connection to one Crazyflie (made by :func:`open_link`)."""

    def __init__(self, *, cf: Any, uri: str, clock: Clock, post: Post) -> None:
        self.cf, self.uri, self.clock, self._post = cf, uri, clock, post
        self.lost = False
        self.stuck = False  # a cflib call never returned (see SEND_TIMEOUT_S): no more calls
        self._caller: _Caller | None = None  # made for the radio driver's first call
        self._configs: list[Any] = []
        cf.connection_lost.add_callback(self._on_lost)
        cf.console.receivedChar.add_callback(
            lambda text: post(("console", clock.now(), text)))
        stats = cf.link_statistics
        stats.link_quality_updated.add_callback(
            lambda q: post(("link", clock.now(), float(q), math.nan)))
        stats.latency_updated.add_callback(
            lambda ms: post(("link", clock.now(), math.nan, float(ms))))

    def _on_lost(self, uri: str, message: str) -> None:
        self.lost = True
        lines = str(message).strip().splitlines()  # cflib may give no reason at all
        self._post(("lost", self.clock.now(), lines[0] if lines else "no reason given"))

    # ------------------------------------------------------------------ TOC and metadata
    def toc_type(self, name: str) -> str | None:
        """The log TOC type of ``group.name`` (``None`` if the firmware has no such variable)."""
        element = self.cf.log.toc.get_element_by_complete_name(name)
        return None if element is None else element.ctype

    def plan_blocks(self, *, blocks: Mapping[str, Sequence[str]],
                    period_s: float) -> list[BlockPlan]:
        """:func:`plan_blocks` against this Crazyflie's TOC."""
        return plan_blocks(toc_type=self.toc_type, blocks=blocks, period_s=period_s)

    def firmware_version(self, *, timeout_s: float = 1.0) -> str:
        """The firmware's version text (platform service), or its revision parameters."""
        from cflib.crtp.crtpstack import CRTPPacket

        got: list[str] = []
        done = threading.Event()

        def on_platform(pk: Any) -> None:
            if pk.channel == _VERSION_CHANNEL and pk.data[:1] == bytes([_VERSION_GET_FIRMWARE]):
                got.append(bytes(pk.data[1:]).split(b"\0")[0].decode("utf-8", "replace"))
                done.set()

        self.cf.add_port_callback(_PLATFORM_PORT, on_platform)
        try:
            pk = CRTPPacket()
            pk.set_header(_PLATFORM_PORT, _VERSION_CHANNEL)
            pk.data = (_VERSION_GET_FIRMWARE,)
            self.cf.send_packet(pk)
            done.wait(timeout_s)
        finally:
            self.cf.remove_port_callback(_PLATFORM_PORT, on_platform)
        if got:
            return got[0]
        fw = self.cf.param.values.get("firmware", {})
        return " ".join(f"{k}={v}" for k, v in sorted(fw.items())) or "unknown"

    def metadata(self) -> dict[str, Any]:
        """Root attributes for the session: uri, firmware, protocol_version, params."""
        return {
            "uri": self.uri,
            "firmware": self.firmware_version(),
            "protocol_version": int(self.cf.platform.get_protocol_version()),
            "params": self._typed_params(),
            **radio_metadata(self.cf),  # radio://: channel, data rate, address, dongle firmware
        }

    def _typed_params(self) -> dict[str, dict[str, float | int | str]]:
        """Parameters read at connect, as numbers typed from the param TOC (cflib keeps the
        text it printed them as)."""
        out: dict[str, dict[str, float | int | str]] = {}
        for group, values in self.cf.param.values.items():
            for name, text in values.items():
                try:
                    ctype = self.cf.param.toc.get_element(group, name).ctype
                    value: float | int | str = typed_value(text, ctype)
                except (AttributeError, KeyError, TypeError, ValueError):
                    value = text  # keep what cflib read rather than lose it
                out.setdefault(group, {})[name] = value
        return out

    # ------------------------------------------------------------------ logging
    def start_blocks(self, blocks: Sequence[BlockPlan]) -> None:
        """Create and start ``blocks``; their packets are posted as ``("log", ...)``."""
        from cflib.crazyflie.log import LogConfig

        for block in blocks:
            conf = LogConfig(name=block.name, period_in_ms=round(block.period_s * 1000))
            for var, ctype in block.variables:
                conf.add_variable(var, ctype)
            names = [v for v, _ in block.variables]
            conf.data_received_cb.add_callback(
                lambda ts, data, c, names=names: self._post(
                    ("log", c.name, self.clock.now(), int(ts), tuple(data[n] for n in names))))
            conf.error_cb.add_callback(
                lambda c, msg: self._post(("log_error", self.clock.now(), f"{c.name}: {msg}")))
            try:
                self.cf.log.add_config(conf)
            except (KeyError, AttributeError) as exc:
                raise LinkError(f"log block {block.name}: cflib refused it ({exc}); "
                                "check the variables and the period") from None
            conf.start()
            self._configs.append(conf)

    # ------------------------------------------------------------------ commander
    def _bounded(self, fn: Callable[[], Any], *, what: str, always: bool = False,
                 timeout_s: float = SEND_TIMEOUT_S,
                 late: Literal["lost", "late_close"] = "lost") -> None:
        """``fn()`` (a cflib call) unless the link is stuck; one that does not return within
        ``timeout_s`` makes the link stuck and is posted as ``late`` (``"lost"`` also marks the
        link lost). Sends are bounded on the radio only (the only driver whose send can block);
        ``always`` bounds ``fn`` on every driver."""
        if self.stuck:
            return
        if not always and not hasattr(self.cf.link, "out_queue"):
            fn()
            return
        if self._caller is None:
            self._caller = _Caller(f"cflib-calls {self.uri}")
        if self._caller.call(fn, timeout_s=timeout_s):
            return
        self.stuck = True
        log.error("cflib did not take the %s within %g s", what, timeout_s)
        if late == "lost" and self.lost:
            return
        self.lost = self.lost or late == "lost"
        why = " (the stop setpoint was delivered before)" if late == "late_close" else (
            ": the radio stopped answering (unplugged?)")
        self._post((late, self.clock.now(),
                    f"cflib did not take the {what} within {timeout_s:g} s{why}"))

    def send_setpoint(self, *, roll: float, pitch: float, yaw_rate: float, thrust: int) -> None:
        """``Commander.send_setpoint`` (deg, deg, deg/s, PWM); cflib negates pitch on the wire."""
        self._bounded(lambda: self.cf.commander.send_setpoint(roll, pitch, yaw_rate,
                                                              int(thrust)), what="setpoint")

    def send_stop(self) -> None:
        """The stop setpoint: motors off at once."""
        self._bounded(self.cf.commander.send_stop_setpoint, what="stop setpoint")

    def request_arming(self) -> None:
        """cflib's ``Supervisor.send_arming_request(True)``: arm a Crazyflie that does not arm
        itself (a Crazyflie Brushless; the legacy platform channel on older firmware)."""
        self._bounded(lambda: self.cf.supervisor.send_arming_request(True),
                      what="arming request")

    def deliver_stop(self) -> None:
        """The stop setpoint, sent :data:`STOP_REPEATS` times :data:`STOP_SPACING_S` apart on
        the flight clock (one lost on the way is sent again), then wait, at most
        :data:`DRAIN_TIMEOUT_S` of wall time, until the link driver's send queue is empty:
        closing the link right after cannot discard it (cflib's radio driver empties its
        queue on close)."""
        for i in range(STOP_REPEATS):
            if i:
                self.clock.sleep_until(self.clock.now() + STOP_SPACING_S)
            self.send_stop()
        out = getattr(self.cf.link, "out_queue", None)  # the radio driver's; others send at once
        give_up = time.monotonic() + DRAIN_TIMEOUT_S
        while out is not None and not out.empty() and time.monotonic() < give_up:
            time.sleep(0.002)
        if out is not None and not out.empty():
            log.warning("the stop setpoint is still queued after %g s", DRAIN_TIMEOUT_S)

    def close(self) -> None:
        """Stop the log blocks and close the link (never raises; a stuck link is left as it
        is, its cflib threads with it)."""
        def close() -> None:
            if not self.lost:
                for conf in self._configs:
                    conf.stop()
            for timer in list(getattr(self.cf, "_answer_patterns", {}).values()):
                timer.cancel()  # cflib's pending resends: none may fire into the close
            _unblock_close(self.cf)
            self.cf.close_link()

        try:
            # on every driver: cflib can deadlock closing a link while one of its resend
            # timers sends (the send lock is not released when the link vanishes under it)
            self._bounded(close, what="link close", always=True,
                          timeout_s=CLOSE_TIMEOUT_S, late="late_close")
        except Exception:  # closing must not hide the flight's own outcome
            log.exception("closing the link to %s failed", self.uri)
        if self.stuck:
            log.warning("the link to %s is stuck in cflib; left open", self.uri)


def _unblock_close(cf: Any) -> None:
    """Let cflib close the link in milliseconds instead of 1-2 s: ``close_link`` joins threads
    that wait up to 1 s before they look at their stop flags, its packet handler (blocked in
    the driver's ``receive_packet(1)``) and the UDP driver's receiver (in ``recv``). Stop both
    and wake them (``None`` is the handler's "no packet"; a shut read side returns ``recv`` at
    once). Nothing is received after this: it runs after the stop setpoint was delivered."""
    driver, incoming = cf.link, getattr(cf, "incoming", None)
    in_queue = getattr(driver, "in_queue", None)
    if incoming is not None and hasattr(incoming, "stop") and in_queue is not None:
        incoming.stop()
        in_queue.put(None)
    from cflib.crtp.udpdriver import UdpDriver  # cflib loads on connecting (tests/test_boundaries)

    thread, sock = getattr(driver, "_thread", None), getattr(driver, "socket", None)
    if isinstance(driver, UdpDriver) and sock is not None and hasattr(thread, "_sp"):
        thread._sp = True
        with contextlib.suppress(OSError):  # not connected, closed: the join waits its 1 s
            sock.shutdown(socket.SHUT_RD)


def open_link(*, uri: str, clock: Clock, post: Post, timeout_s: float = 10.0,
              limit_s: float = CONNECT_LIMIT_S, cancel: threading.Event | None = None) -> Link:
    """Connect to ``uri`` and wait until every parameter has been read (``fully_connected``).

    ``timeout_s`` is the longest the vehicle may stay silent while connecting (wall-clock
    seconds without a packet from it: nothing at that address, or a link that lost a request
    and cannot resend); a connection that keeps answering may take longer, a slow link or a
    starved host fetching a large TOC, but at most ``limit_s`` in all. Setting ``cancel``
    (Ctrl-C while connecting) gives up at once. Failure raises a one-line :class:`LinkError`.
    """
    check_uri(uri)
    install_drivers()
    log_cflib_thread_errors()  # a dying link's cflib threads: one line, not a traceback
    check_dongle(uri)  # no dongle, too old a firmware: one line with the fix
    from cflib.crazyflie import Crazyflie

    # Without a cache folder cflib warns on every connect that it cannot save the TOC.
    logging.getLogger("cflib.crazyflie.toccache").setLevel(logging.ERROR)
    cache = toc_cache_dir()
    cf = Crazyflie(rw_cache=None if cache is None else str(cache))
    ready, failure = threading.Event(), []
    cf.fully_connected.add_callback(lambda _uri: ready.set())

    def failed(_uri: str, message: str) -> None:
        failure.append(str(message).strip().splitlines()[0] if str(message).strip() else "")
        ready.set()

    cf.connection_failed.add_callback(failed)
    cf.connection_lost.add_callback(failed)
    heard = [-math.inf]  # when the vehicle last sent anything

    def answered(_pk: Any) -> None:
        heard[0] = time.monotonic()

    cf.packet_received.add_callback(answered)
    link = Link(cf=cf, uri=uri, clock=clock, post=post)
    t0 = time.monotonic()
    cf.open_link(uri)
    heard[0] = max(heard[0], time.monotonic())  # the silence counts once the link is open
    while not ready.wait(0.05):
        now = time.monotonic()
        if cancel is not None and cancel.is_set():
            failure.append("connect cancelled")
        elif now - heard[0] > timeout_s:
            failure.append(f"no answer within {timeout_s:g} s")
        elif now - t0 > limit_s:
            failure.append(f"the vehicle answers but the connection was not complete after "
                           f"{limit_s:g} s")
        else:
            continue
        break
    cf.packet_received.remove_callback(answered)
    if failure:
        link.close()  # bounded (Link.close)
        why = failure[0]
        raise LinkError(f"cannot connect to {uri}: {why}; {connect_advice(why, uri=uri)}")
    cf.connection_failed.remove_callback(failed)
    cf.connection_lost.remove_callback(failed)
    log.info("connected to %s in %.2f s", uri, time.monotonic() - t0)
    return link
