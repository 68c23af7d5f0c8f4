"""The real Crazyflie firmware in the loop: the SITL executable, our physics, a relay for cflib.

The firmware (CrazySim's ``sitl-release`` build, GPL-3.0) is an ordinary program that ``make
sitl`` builds into ``.sitl/cf2`` of the checkout; it is never part of the Python package. Started
as ``cf2 PORT 127.0.0.1`` it sends ``0xF3`` to ``PORT`` and waits for ``0xF3`` back, then talks
CRTP over that UDP socket (see ``shared/sitl/README.md``). :class:`SitlVehicle` plays the peer:

* **physics**: a 1 kHz real-time loop that takes the firmware's motor commands, steps
  :class:`~groundstation.sim.physics_peer.PhysicsPeer` (the ``sim://`` rigid body, battery and
  sensors) and sends the IMU (1 kHz), barometer (50 Hz) and external pose (200 Hz);
* **relay**: cflib's UDP protocol on ``udp://HOST:PORT``, with the simulator's client policy
  (:mod:`groundstation.sim.client_policy`): one client at a time, the first address to send a
  non-null packet, until it disconnects or goes silent for 1 s of wall-clock time; its packets go
  to the firmware and every other packet of the firmware goes to it. Datagrams of anyone else
  are ignored, counted in ``foreign`` and logged once; a single ``0xFF`` byte is cflib's scan
  probe and is answered with ``0xFF`` whoever sends it. The relay binds 127.0.0.1 unless told
  otherwise; an address other machines reach needs ``allow_remote`` and logs a warning.

The firmware process dies with its parent (``PR_SET_PDEATHSIG``), so a killed ground station
leaves no orphan; :meth:`SitlVehicle.close` stops it otherwise.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

from groundstation.errors import GroundStationError, LinkError
from groundstation.sim.client_policy import ClientLink, check_host
from groundstation.sim.physics_peer import (
    BARO_EVERY,
    BATTERY_EVERY,
    GYRO_BIAS_FOUND,
    POSE_EVERY,
    PhysicsPeer,
    parse_motor_packet,
)

__all__ = [
    "FIRMWARE_ENV",
    "FirmwareError",
    "SitlServer",
    "SitlVehicle",
    "die_with_parent",
    "find_firmware",
]

log = logging.getLogger(__name__)

FIRMWARE_ENV = "CF_SITL_FIRMWARE"
"""Environment variable naming the ``cf2`` executable (default: ``.sitl/cf2`` of the checkout)."""
_HANDSHAKE = b"\xf3"
_ACC_SCALE_STEPS = 1000   # IMU samples the firmware averages for its accelerometer scale
_MAX_LAG_S = 0.05         # behind the wall clock by more than this: slip instead of bursting
_HOLD_AFTER_STEPS = 8     # IMU samples without a motor command (normal: 1-3) before holding
_HOLD_MAX_S = 0.05        # longest hold before one more sample goes out
_PR_SET_PDEATHSIG = 1


class FirmwareError(GroundStationError, RuntimeError):
    """The SITL firmware is missing, did not start, or exited."""


def find_firmware() -> Path:
    """The ``cf2`` executable: ``$CF_SITL_FIRMWARE``, else ``.sitl/cf2`` next to the package.

    Raises :class:`FirmwareError` (one line: how to build it) when there is none.
    """
    env = os.environ.get(FIRMWARE_ENV)
    path = Path(env) if env else Path(__file__).resolve().parents[2] / ".sitl" / "cf2"
    if not (path.is_file() and os.access(path, os.X_OK)):
        raise FirmwareError(f"no SITL firmware at {path}; build it with `make sitl` "
                            f"(or set {FIRMWARE_ENV})")
    return path


def die_with_parent() -> None:
    """``preexec_fn`` for a child that must not outlive its parent: SIGKILL when it dies.

    Linux only (``prctl``); elsewhere a no-op. The signal fires when the thread that started the
    child exits, so start children from a thread that lives as long as they should.
    """
    with contextlib.suppress(OSError, AttributeError):
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    if os.getppid() == 1:  # the parent died before prctl took effect
        os._exit(1)


def _bind(host: str, port: int, what: str) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise LinkError(f"cannot listen on udp://{host}:{port} for {what} ({exc.strerror}); "
                        "choose another --port") from None
    return sock


class SitlVehicle:
    """One firmware process, its physics peer and its cflib relay on ``udp://host:port``.

    The relay serves one client at a time (``client``; others counted in ``foreign``) and binds
    a ``host`` other machines reach only with ``allow_remote``. Starts at once;
    :meth:`wait_ready` returns when the firmware has calibrated its sensors (about 3 s) and
    raises :class:`FirmwareError` if it exits or does not answer. Use as a context manager or
    call :meth:`close`.
    """

    def __init__(self, *, firmware: Path, host: str = "127.0.0.1", port: int = 19850,
                 seed: int = 0, handshake_timeout_s: float = 10.0,
                 allow_remote: bool = False) -> None:
        host = check_host(host, allow_remote=allow_remote,
                          what=f"the vehicle on udp port {port}")
        self.host, self.port = host, port
        self.peer = PhysicsPeer(seed=seed)
        self.slips = 0            # times the loop fell > 50 ms behind the wall clock
        self.held_s = 0.0         # time the physics waited for a lagging firmware
        self.relayed = [0, 0]         # packets firmware -> client, client -> firmware
        self.ready = threading.Event()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._bias_step: int | None = None
        self.proc: subprocess.Popen | None = None
        self.relay = _bind(host, port, "cflib")
        # The firmware runs in real time: the client's silence is measured by the wall clock.
        self.link = ClientLink(self.relay, name=f"sitl {port}", clock=time.monotonic)
        try:
            self.sock = _bind("127.0.0.1", 0, "the firmware")
        except BaseException:
            self.relay.close()
            raise
        try:
            self._start(firmware, handshake_timeout_s)
        except BaseException:
            self.close()
            raise

    # ------------------------------------------------------------------ start and stop
    def _start(self, firmware: Path, timeout_s: float) -> None:
        peer_port = self.sock.getsockname()[1]
        try:
            self.proc = subprocess.Popen(
                [str(firmware), str(peer_port), "127.0.0.1"], stdin=subprocess.DEVNULL,
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                preexec_fn=die_with_parent, start_new_session=True)
        except OSError as exc:
            raise FirmwareError(f"cannot start the SITL firmware {firmware}: {exc}") from None
        self.sock.settimeout(0.1)
        deadline = time.monotonic() + timeout_s
        while True:
            if self.proc.poll() is not None:
                raise FirmwareError(f"the SITL firmware exited at start-up ({self._exit_text()})")
            if time.monotonic() > deadline:
                raise FirmwareError(f"the SITL firmware sent no handshake in {timeout_s:g} s")
            try:
                data, addr = self.sock.recvfrom(64)
            except TimeoutError:
                continue
            if data == _HANDSHAKE:
                break
        self.fw_addr = addr
        self.sock.sendto(_HANDSHAKE, addr)
        self.sock.setblocking(False)
        self.relay.settimeout(0.2)
        log.info("SITL firmware pid %d on udp %d, cflib relay on udp://%s:%d",
                 self.proc.pid, peer_port, self.host, self.port)
        for target, name in ((self._physics, "physics"), (self._relay, "relay")):
            t = threading.Thread(target=target, name=f"sitl-{name}-{self.port}", daemon=True)
            t.start()
            self._threads.append(t)

    def _exit_text(self) -> str:
        code = self.proc.returncode if self.proc else None
        if code is not None and code < 0:
            return f"killed by signal {signal.Signals(-code).name}"
        return f"exit code {code}"

    @property
    def uri(self) -> str:
        """cflib's URI of this vehicle, e.g. ``udp://127.0.0.1:19850``."""
        return f"udp://{self.host}:{self.port}"

    @property
    def client(self) -> tuple[str, int] | None:
        """The address the relay serves (None: the link is free)."""
        return self.link.client

    @property
    def foreign(self) -> int:
        """Datagrams the relay ignored because they came from another address than the client's."""
        return self.link.foreign

    @property
    def alive(self) -> bool:
        """True while the firmware process runs."""
        return self.proc is not None and self.proc.poll() is None

    def wait_ready(self, *, timeout_s: float = 30.0) -> None:
        """Block until the firmware's sensors are calibrated; :class:`FirmwareError` otherwise."""
        deadline = time.monotonic() + timeout_s
        while not self.ready.wait(0.1):
            if not self.alive:
                raise FirmwareError(f"the SITL firmware exited ({self._exit_text()})")
            if time.monotonic() > deadline:
                raise FirmwareError(f"the SITL firmware did not calibrate in {timeout_s:g} s")

    def close(self) -> None:
        """Stop the loops and the firmware process (SIGTERM, then SIGKILL) and free the ports."""
        self._stop.set()
        for t in self._threads:
            t.join(timeout=2)
        self._threads = []
        proc, self.proc = self.proc, None
        if proc is not None and proc.poll() is None:
            proc.terminate()
            try:
                proc.wait(timeout=2)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=2)
        self.proc = proc
        self.relay.close()
        self.sock.close()

    def __enter__(self) -> SitlVehicle:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ the two loops
    def _from_firmware(self, step: int) -> bool:
        """Drain the firmware's datagrams: motors to the physics, the rest to the client.
        Returns whether a motor command came."""
        sock, peer = self.sock, self.peer
        motor = False
        while True:
            try:
                data, addr = sock.recvfrom(64)
            except (BlockingIOError, InterruptedError):
                return motor
            except OSError as exc:
                if not self._stop.is_set():
                    log.debug("sitl %d: firmware socket: %s", self.port, exc)
                return motor
            if addr != self.fw_addr:
                continue
            motors = parse_motor_packet(data)
            if motors is not None:
                peer.set_motors(motors)
                motor = True
            elif data == GYRO_BIAS_FOUND:
                self._bias_step = step
            elif self.link.send(data):
                self.relayed[0] += 1

    def _physics(self) -> None:
        peer, sock, fw = self.peer, self.sock, self.fw_addr
        period = 0.001
        next_t = time.perf_counter()
        step = 0
        since_motor = -1      # steps since the last motor command (-1: none yet)
        hold_until = 0.0
        try:
            while not self._stop.is_set():
                if self._from_firmware(step):
                    since_motor = 0
                if since_motor >= _HOLD_AFTER_STEPS:
                    # The firmware is behind (starved host): hold the physics rather than fly on
                    # with stale motor commands, but nudge it every _HOLD_MAX_S so it never waits.
                    now = time.perf_counter()
                    if hold_until == 0.0:
                        hold_until = now + _HOLD_MAX_S
                    if now < hold_until:
                        self.held_s += 0.0005
                        time.sleep(0.0005)
                        next_t = time.perf_counter()
                        continue
                    hold_until = 0.0
                elif hold_until:
                    hold_until = 0.0
                if since_motor >= 0:
                    since_motor += 1
                imu = peer.step()
                step += 1
                sock.sendto(imu, fw)
                if step % BARO_EVERY == 0:
                    sock.sendto(peer.barometer_packet(), fw)
                if step % POSE_EVERY == 0:
                    sock.sendto(peer.pose_packet(), fw)
                if step % BATTERY_EVERY == 1:  # from the first step: pm.vbat is never 0
                    sock.sendto(peer.battery_packet(), fw)
                if self._bias_step is not None and step - self._bias_step >= _ACC_SCALE_STEPS:
                    self.ready.set()
                if step % 250 == 0 and self.proc is not None and self.proc.poll() is not None:
                    log.error("sitl %d: the firmware exited (%s)", self.port, self._exit_text())
                    return
                next_t += period
                delay = next_t - time.perf_counter()
                if delay > 0:
                    time.sleep(delay)
                elif delay < -_MAX_LAG_S:
                    next_t = time.perf_counter()
                    self.slips += 1
        except OSError as exc:
            if not self._stop.is_set():
                log.error("sitl %d: physics loop stopped: %s", self.port, exc)

    def _relay(self) -> None:
        link, sock = self.link, self.sock
        while not self._stop.is_set():
            data = link.receive()
            if data is None:
                continue
            with contextlib.suppress(OSError):
                sock.sendto(data, self.fw_addr)
                self.relayed[1] += 1


class SitlServer:
    """``vehicles`` firmware instances on ``udp://host:port`` .. ``port + vehicles - 1``.

    Binds 127.0.0.1 unless ``host`` says otherwise (an address other machines reach, ``""``
    and ``0.0.0.0`` included, needs ``allow_remote=True`` and logs a warning); every vehicle
    runs in real time (about a tenth of a core each for the physics loop) and serves one client
    at a time. Raises :class:`FirmwareError` when the firmware is missing or does not start; use
    as a context manager or call :meth:`close`.
    """

    def __init__(self, *, host: str = "127.0.0.1", port: int = 19850, vehicles: int = 1,
                 seed: int = 0, firmware: Path | None = None, allow_remote: bool = False) -> None:
        # Refuse a host before looking for the firmware; each vehicle warns about its own port.
        host = check_host(host, allow_remote=allow_remote, what="the vehicle", warn=False)
        if not 1 <= vehicles <= 10:
            raise LinkError(f"--vehicles {vehicles} is out of range; serve 1 to 10 vehicles")
        if not 1 <= port <= 65535 - vehicles + 1:
            raise LinkError(f"--port {port} is out of range; use 1..{65536 - vehicles}")
        fw = firmware or find_firmware()
        self.vehicles: list[SitlVehicle] = []
        try:
            for i in range(vehicles):
                self.vehicles.append(SitlVehicle(firmware=fw, host=host, port=port + i,
                                                 seed=seed + i, allow_remote=allow_remote))
        except BaseException:
            self.close()
            raise

    @property
    def uris(self) -> list[str]:
        return [v.uri for v in self.vehicles]

    def wait_ready(self, *, timeout_s: float = 30.0) -> None:
        """Every vehicle calibrated (see :meth:`SitlVehicle.wait_ready`)."""
        for v in self.vehicles:
            v.wait_ready(timeout_s=timeout_s)

    def dead(self) -> list[SitlVehicle]:
        """Vehicles whose firmware process has exited."""
        return [v for v in self.vehicles if not v.alive]

    def close(self) -> None:
        for v in self.vehicles:
            v.close()
        self.vehicles = []

    def __enter__(self) -> SitlServer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
