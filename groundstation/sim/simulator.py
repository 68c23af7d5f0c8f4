"""The simulation behind a ``sim://`` URI (options: :mod:`groundstation.sim.uri`; one per URI:
:mod:`groundstation.sim.registry`): a simulated Crazyflie on its own thread.

A :class:`Simulator` steps the vehicle from one thread at ``speed`` x real time, splitting its steps
at the firmware ms where log packets are due, so every log packet carries the exact firmware time;
a scheduler sleeping on its clock paces it (:meth:`Simulator.pace`); flat out (``speed=inf``) it
also runs in lock-step with its link (:attr:`Simulator.quiescent`), so same-seed flights are
identical, and its commander packets take effect a seeded per-flight delay of 0-19 ms after they
are handled, as a radio's land at no fixed phase of the 50 Hz logs. Faults act on what the link
returns (log packets dropped, everything delayed); a cut link stops both directions and fires the
link's error callback, the vehicle left to its supervisor watchdog. A lost link (``cut_at``)
leaves the simulation running until the vehicle has been at rest for a second, as a real one
would; :func:`groundstation.sim.registry.instance` reaches it for inspection. The cflib side:
:mod:`groundstation.sim.driver`.
"""

from __future__ import annotations

import logging
import math
import random
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any

from groundstation.sim.clock import SimClock
from groundstation.sim.crtp import CrtpPeer
from groundstation.sim.crtp_wire import P_COMMANDER, P_GENERIC, Packet, crtp_port
from groundstation.sim.radio_phase import RadioPhase
from groundstation.sim.uri import Faults

__all__ = ["Simulator"]

logger = logging.getLogger(__name__)

_WAKE_S = 0.010  # longest the simulation thread sleeps (wall s) between steps
_CLOCK_RESOLUTION_MS = 40  # ... and at most this much simulation time
_CHUNK_MS = 10  # longest single vehicle.advance() so commands are applied promptly
_MAX_LAG_MS = 200  # when the host cannot keep up, simulation time slips beyond this lag
_PACE_LEAD_MS = 5  # a paced simulation runs at most this far past the scheduler's wake time
_COMMANDER_PORTS = (P_COMMANDER, P_GENERIC)  # RPYT setpoints; stop and notify-stop: lock-step
# delays them as a radio would (groundstation.sim.radio_phase)
_PACE_HOLD_S = 3.0  # ... and holds there at most this long (wall s) for the scheduler: only a
# scheduler that stops sleeping mid-link (a stalled or crashed client) ever waits it out
_DETACHED_HOLD_S = 0.2  # once the link has detached, at most this long: a flight that has not
# heard of a lost link yet (cflib reports it ~80 ms of wall time after it closes the link) still
# holds time, and the vehicle's watchdog runs on soon after the flight stops sleeping
_REST_S = 1.0  # a lingering simulation (no link) powers off after this long at rest
_NEVER_ATTACHED_S = 10.0  # ... or this long if no link ever attached (created by its clock)


class Simulator:
    """One simulated Crazyflie: a vehicle, its :class:`CrtpPeer`, and the thread stepping them.

    Packets come in through :meth:`submit` and go out through :meth:`receive` (the ``sim://``
    driver) or, when ``sink`` is given, straight to ``sink(header, payload)`` from the simulation
    thread (the UDP server). ``linger=False`` keeps it running until :meth:`close`. With
    ``link_timeout_ms`` (simulation ms) silence on the link resets logging as the firmware does;
    ``None`` (the ``sim://`` link, whose client pings on wall time) ties it to attach/detach/cut.
    """

    def __init__(self, *, address: str = "0", speed: float = 1.0, seed: int = 0,
                 vehicle: Any = None, sink: Callable[[int, bytes], None] | None = None,
                 linger: bool = True, link_timeout_ms: int | None = None,
                 max_backlog: int | None = None, auto_arm: bool = True) -> None:
        if vehicle is None:
            from groundstation.sim.vehicle import SimVehicle

            vehicle = SimVehicle(seed=seed, auto_arm=auto_arm)
        self.address, self.speed, self.vehicle = address, speed, vehicle
        self.peer = CrtpPeer(vehicle=vehicle, link_timeout_ms=link_timeout_ms)
        self.faults = Faults()
        self.cond = threading.Condition()
        self.clock = SimClock(source=self)
        self.dropped_packets = 0  # log packets lost to the drop fault
        self._rng = random.Random(seed * 7919 + 17)
        self._radio = RadioPhase(seed=seed)  # lock-step: commander packets' radio delay
        self._sink, self._linger = sink, linger
        self._rx: deque[tuple[int, int, bytes]] = deque()
        self._out: deque[tuple[int, int, bytes]] = deque()  # (release ms, header, payload)
        self._published_ms = vehicle.firmware_ms
        self._published_s = vehicle.time_s
        self._token = 0  # the link currently attached (0: none)
        self._last_token = 0  # tokens only grow: a late packet of an old link is never taken
        self._closed: set[int] = set()  # links detached whose link-down marker waits in _rx
        self._ever_attached = False
        self._cut = False
        # lock-step: a cut's report to the link (cflib closes it, then tells the flight: ~80 ms
        # of wall time) holds time until it is through, so the flight hears of it on time
        self._reporting: threading.Thread | None = None
        self._cut_wall = 0.0
        self._on_lost: Callable[[str], None] | None = None
        self._pace_ms: int | None = None  # paced: run no further than this (see pace())
        self._pace_wall = 0.0
        # Flat out: lock-step with the link (see quiescent). Time starts held for the scheduler,
        # so connecting costs no simulated time however long it takes on the host.
        self._lockstep = math.isinf(speed) and sink is None
        if self._lockstep:
            self._pace_ms, self._pace_wall = vehicle.firmware_ms, time.monotonic()
        self._handed = False  # a packet is in the link's hands (it has not asked for more since)
        self._link_wall = time.monotonic()  # when the link last took or asked for a packet
        # A link that fetches packets one by one (the emulated radio's acks) holds simulation
        # time while this many wait for it, as a link faster than the host would never fall
        # behind (the hold lapses like the pacing hold when nothing is fetched for 3 s).
        self._max_backlog, self._taken_wall = max_backlog, time.monotonic()
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"sim-{address}", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ clock source
    @property
    def published_s(self) -> float:
        return self._published_s

    @property
    def running(self) -> bool:
        return not self._stop.is_set()

    @property
    def quiescent(self) -> bool:
        """Lock-step, flat out: the simulation holds where the scheduler's sleep lets it, has
        handled every packet sent to it, and the link has taken every released packet and come
        back for more (cflib's thread has run their callbacks). Time starts held (connecting
        costs no simulated time) and moves only while the link is idle, so what the scheduler
        and the link read never depends on thread timing; a cut link holds it until the link
        has been told (cflib has closed it and told the flight). Always true at a finite
        speed; true once a hold lapses (``_PACE_HOLD_S``), so nothing ever hangs on it."""
        with self.cond:
            if not self._lockstep:
                return True
            lapsed = time.monotonic() - self._pace_wall > self._hold_s()
            held = self._pace_ms is None or lapsed or self._published_ms >= self._pace_ms
            reporting = (self._reporting is not None and self._reporting.is_alive()
                         and time.monotonic() - self._cut_wall < _PACE_HOLD_S)
            return held and not self._rx and self._link_idle() and not reporting

    def _link_idle(self) -> bool:
        """(under ``cond``) Lock-step: nothing released waits for the link or is in its hands
        (a link silent for ``_PACE_HOLD_S`` counts as idle: time never waits on a stuck one)."""
        if not self._token or time.monotonic() - self._link_wall > _PACE_HOLD_S:
            return True
        return not self._handed and not (self._out and self._out[0][0] <= self._published_ms)

    def pace(self, *, until_s: float) -> None:
        """A scheduler sleeps until ``until_s``: let the simulation run to it and then hold,
        at most ``_PACE_LEAD_MS`` past it, until the scheduler sleeps again (or ``_PACE_HOLD_S``
        of wall time passes, or the link detaches). A host too busy to wake its scheduler on time
        thus freezes simulation time instead of making setpoints late: at speed 20, 25 ms of GIL
        contention would otherwise be a 500 ms setpoint gap, which makes the firmware re-lock the
        thrust.
        """
        ms = math.ceil(until_s * 1000.0) + _PACE_LEAD_MS
        with self.cond:
            if self._pace_ms is None or ms > self._pace_ms:
                self._pace_ms = ms
            self._pace_wall = time.monotonic()
        self._wake.set()

    def _paced_target(self, target: int) -> int:
        """``target`` capped at the pace limit while a scheduler holds the simulation."""
        with self.cond:
            limit, since, hold_s = self._pace_ms, self._pace_wall, self._hold_s()
            behind = (self._max_backlog is not None and self._token != 0
                      and len(self._out) >= self._max_backlog
                      and time.monotonic() - self._taken_wall < _PACE_HOLD_S)
            behind = behind or (self._lockstep and not self._link_idle())
        if behind:
            return min(target, self.vehicle.firmware_ms)
        if limit is None or time.monotonic() - since > hold_s:
            return target
        return min(target, max(limit, self.vehicle.firmware_ms))

    def _hold_s(self) -> float:
        """(under ``cond``) How long a hold lasts past the scheduler's last sleep (wall s): a
        link that has detached (closed, or lost: cflib closes it on the error) shortens it to
        :data:`_DETACHED_HOLD_S`. Time held there keeps a flight that has not heard of the loss
        yet on the simulation clock (it ran free before: at ``speed=inf`` the loss was recorded
        0.3-26 s of simulated time late, a different time each run); held long, the vehicle
        would stand still (its watchdog with it) once the flight has gone."""
        return _DETACHED_HOLD_S if self._ever_attached and not self._token else _PACE_HOLD_S

    # ------------------------------------------------------------------ faults API
    def set_faults(self, *, drop: float | None = None, latency_ms: float | None = None,
                   cut_at: float | None = None) -> None:
        """Change link faults while running (``None`` leaves a fault as it is)."""
        with self.cond:
            if drop is not None:
                self.faults.drop = drop
            if latency_ms is not None:
                self.faults.latency_ms = latency_ms
            if cut_at is not None:
                self.faults.cut_at = cut_at

    def cut_link(self) -> None:
        """Cut the link now (at the current simulation time)."""
        self.set_faults(cut_at=self._published_s)

    # ------------------------------------------------------------------ link side
    def attach(self, *, faults: Faults | None = None,
               on_lost: Callable[[str], None] | None = None) -> int:
        """Attach a new link (replacing any other); returns its token."""
        with self.cond:
            self._last_token += 1
            self._token = self._last_token
            self._ever_attached, self._cut, self._on_lost = True, False, on_lost
            self.faults = faults or Faults()
            self._out.clear()
            return self._token

    def detach(self, *, token: int) -> None:
        """The link ``token`` is gone; nothing more goes out to it."""
        with self.cond:
            if token == self._token:
                self._closed.add(token)  # before the token goes: its packets still land
                self._token, self._on_lost = 0, None
                self._out.clear()
                self._rx.append((-1, token, b""))  # tells the simulation thread: link down
                self._wake.set()
                self.cond.notify_all()

    def submit(self, *, header: int, data: bytes, token: int = 0) -> None:
        """An incoming packet (from link ``token``; 0 for a transport without tokens)."""
        self._rx.append((token, header, bytes(data)))
        self._wake.set()

    def receive(self, *, token: int, wait: float) -> Packet | None:
        """The next released outgoing packet for link ``token`` (``wait`` as cflib's driver)."""
        deadline = None if wait < 0 else time.monotonic() + wait
        with self.cond:
            if token == self._token:
                back, self._handed = self._handed, False  # its last packet's callbacks ran
                self._link_wall = time.monotonic()
            else:
                back = False
            while True:
                if token != self._token or not self.running:
                    return None
                if self._out and self._out[0][0] <= self._published_ms:
                    _, header, data = self._out.popleft()
                    self._handed = True
                    if self._max_backlog is not None:
                        self._taken_wall = time.monotonic()
                        if len(self._out) < self._max_backlog:
                            self._wake.set()
                    return header, data
                if back and self._lockstep:  # drained: time may move on (lock-step)
                    back = False
                    self._wake.set()
                    self.cond.notify_all()
                remaining = 0.1 if deadline is None else deadline - time.monotonic()
                if remaining <= 0:
                    return None
                self.cond.wait(min(remaining, 0.1))

    def close(self) -> None:
        """Power off: stop the simulation thread and wait for it."""
        self._stop.set()
        self._wake.set()
        if self._thread is not threading.current_thread():
            self._thread.join(timeout=5)
        with self.cond:
            self.cond.notify_all()

    # ------------------------------------------------------------------ simulation thread
    def _emit(self, packets: list[Packet], *, log: bool = False) -> None:
        if not packets or self._cut:
            return
        faults = self.faults
        release = self.vehicle.firmware_ms + int(faults.latency_ms)
        with self.cond:
            for header, data in packets:
                if log and faults.drop and self._rng.random() < faults.drop:
                    self.dropped_packets += 1
                    continue
                self._out.append((release, header, data))

    def _process_rx(self) -> None:
        peer, rx = self.peer, self._rx
        self._check_cut()  # a cut due now drops this batch too, also while time is held
        while rx:
            token, header, data = rx.popleft()
            if token == -1:  # link ``header`` detached
                self._apply_delayed(flush=True)  # what was sent before the link closed lands
                self._closed.discard(header)
                peer.link_down()
                continue
            if self._cut or not self._from_link(token):
                continue
            if self._lockstep and crtp_port(header) in _COMMANDER_PORTS:
                self._radio.hold(now_ms=self.vehicle.firmware_ms, token=token, header=header,
                                 data=data)
                continue
            self._emit(peer.handle(header=header, data=data))
        self._apply_delayed()

    def _apply_delayed(self, *, flush: bool = False) -> None:
        """Lock-step: the commander packets whose radio delay has passed (``flush``: all of
        them, the stop setpoint included) take effect."""
        for token, header, data in self._radio.due(now_ms=self.vehicle.firmware_ms, flush=flush):
            if self._from_link(token):  # handled before any cut: it is on board already
                self._emit(self.peer.handle(header=header, data=data))

    def _from_link(self, token: int) -> bool:
        """A packet of the attached link, or of the one just detached (sent before it closed: the
        stop setpoint before a close must land), not of a link another has replaced."""
        return not token or token == self._token or token in self._closed

    def _check_cut(self) -> None:
        cut_at = self.faults.cut_at
        if self._cut or cut_at is None or self.vehicle.time_s < cut_at:
            return
        with self.cond:
            self._cut, on_lost = True, self._on_lost
            self._out.clear()
        self.peer.link_down()
        logger.info("sim-%s: link cut at %.3f s", self.address, self.vehicle.time_s)
        if on_lost is not None:  # off this thread: cflib's handlers may block or close the link
            report = threading.Thread(target=on_lost, args=("simulated radio link lost (cut_at)",),
                                      name=f"sim-{self.address}-lost", daemon=True)
            with self.cond:
                self._reporting, self._cut_wall = report, time.monotonic()
            report.start()

    def _advance_to(self, target_ms: int) -> None:
        v, peer = self.vehicle, self.peer
        while v.firmware_ms < target_ms and not self._stop.is_set():
            now = v.firmware_ms
            step_to = min(target_ms, now + _CHUNK_MS)
            due = peer.next_due_ms()
            if due is not None and now < due < step_to:
                step_to = due
            radio_due = self._radio.next_due_ms()
            if radio_due is not None and now < radio_due < step_to:
                step_to = radio_due
            v.advance((step_to - now) / 1000.0)
            self._emit(peer.due_log_packets(), log=True)
            self._check_cut()
            if self._rx:
                self._process_rx()
            elif self._radio.next_due_ms() is not None:
                self._apply_delayed()

    def _flush_sink(self) -> None:
        out, sink = self._out, self._sink
        while out and out[0][0] <= self._published_ms:
            with self.cond:
                _, header, data = out.popleft()
            sink(header, data)

    def _sleep_s(self, base_wall: float, base_ms: int) -> float:
        """Wall seconds until the next log packet is due, within [0.5 ms, the clock's
        resolution]: 10 ms of wall time, or 40 ms of simulation time at high speed."""
        longest = min(_WAKE_S, _CLOCK_RESOLUTION_MS / 1000.0 / self.speed)
        due = self.peer.next_due_ms()
        if due is None:
            return longest
        until = base_wall + (due - base_ms) / (1000.0 * self.speed) - time.perf_counter()
        return min(longest, max(until, 0.0005))

    def _should_power_off(self, rest_since: float | None) -> bool:
        if not self._linger or self._token:
            return False
        limit = _REST_S if self._ever_attached else _NEVER_ATTACHED_S
        return rest_since is not None and time.monotonic() - rest_since > limit

    def _run(self) -> None:
        v = self.vehicle
        base_wall, base_ms = time.perf_counter(), v.firmware_ms
        rest_since: float | None = time.monotonic()
        failed = False
        while not self._stop.is_set():
            if math.isinf(self.speed):  # flat out, but held for a scheduler like any speed
                # The hold is read first: what the scheduler sent before it released the hold is
                # applied at the held time, never one step later; in lock-step the replies go
                # out (and come back through the link) before time moves on.
                target = self._paced_target(v.firmware_ms + _CHUNK_MS)
                had_rx = bool(self._rx)
                self._process_rx()
                if had_rx and self._lockstep:
                    target = self._paced_target(v.firmware_ms + _CHUNK_MS)
                held = target <= v.firmware_ms
            else:
                self._process_rx()
                target = base_ms + int((time.perf_counter() - base_wall) * self.speed * 1000.0)
                if target - v.firmware_ms > _MAX_LAG_MS:  # host too slow: let time slip
                    base_ms -= target - v.firmware_ms - _MAX_LAG_MS
                    target = v.firmware_ms + _MAX_LAG_MS
                paced = self._paced_target(target)
                if paced < target:  # held for the scheduler: time resumes from here later
                    base_ms -= target - paced
                    target = paced
            try:
                self._advance_to(target)
            except Exception:
                if not failed:
                    logger.exception("sim-%s: vehicle step failed", self.address)
                failed = True
            self._emit(self.peer.console_packets())
            with self.cond:
                self._published_ms, self._published_s = v.firmware_ms, v.time_s
                self.cond.notify_all()
            if self._sink is not None:
                self._flush_sink()
            at_rest = not v.is_flying and not any(v.motors_pwm)
            if not at_rest or self._token:
                rest_since = None
            elif rest_since is None:
                rest_since = time.monotonic()
            if self._should_power_off(rest_since):
                logger.info("sim-%s: no link and at rest: powered off", self.address)
                self._stop.set()
                break
            if not math.isinf(self.speed):
                self._wake.wait(self._sleep_s(base_wall, base_ms))
                self._wake.clear()
            elif held:  # until the scheduler's next sleep_until (or a packet)
                self._wake.wait(_WAKE_S)
                self._wake.clear()
        # Powered off (or at rest with no link): what was sent before lands first, the stop
        # setpoint of a link closed right before included.
        self._process_rx()
        self._apply_delayed(flush=True)
        with self.cond:
            self.cond.notify_all()
