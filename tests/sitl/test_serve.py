"""``groundstation sim --firmware``: the real firmware served on loopback to one client at a time,
answering cflib's scan probe, refusing a host others reach without --allow-remote, and no
firmware process left behind after Ctrl-C, SIGTERM, a killed server or a dead parent. Skipped
when ``make sitl`` has not built the firmware."""

from __future__ import annotations

import contextlib
import os
import queue
import re
import signal
import socket
import struct
import subprocess
import sys
import threading
import time

import pytest
from cflib.crtp.crtpstack import CRTPPacket, CRTPPort

from groundstation.flight.link import install_drivers
from groundstation.sim.crtp import crtp_header
from groundstation.sim.sitl import SitlVehicle

from ..sim_crtp.helpers import connect
from .backend import firmware_or_skip, free_udp_port

CLI = [sys.executable, "-c", "from groundstation.cli import main; main()"]
SERVE = "sim --firmware --port {port}"
# Start a server from an intermediate process that then waits (to be killed in the test).
PARENT = ("import subprocess, sys, time; p = subprocess.Popen(sys.argv[1:]); "
          "print(p.pid, flush=True); time.sleep(600)")


def _default_sigint() -> None:  # a backgrounded test run ignores SIGINT; its children inherit it
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _gone(pid: int, timeout_s: float = 15.0) -> bool:
    """True once ``pid`` has exited (a zombie awaiting its reaper counts as exited)."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            with open(f"/proc/{pid}/stat") as f:
                if f.read().rsplit(")", 1)[1].split()[0] == "Z":
                    return True
        except FileNotFoundError:
            return True
        if time.monotonic() > deadline:
            return False
        time.sleep(0.05)


def _read_until(proc: subprocess.Popen, pattern: str, timeout_s: float = 60.0) -> str:
    """The server's output so far once it matches ``pattern`` (lines come through a thread)."""
    lines: queue.SimpleQueue = proc.lines  # type: ignore[attr-defined]
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        try:
            line = lines.get(timeout=0.2)
        except queue.Empty:
            continue
        if line is None:
            break
        proc.seen += line  # type: ignore[attr-defined]
        if re.search(pattern, proc.seen, re.MULTILINE):  # type: ignore[attr-defined]
            return proc.seen  # type: ignore[attr-defined]
    raise AssertionError(f"no {pattern!r} in the output: {proc.seen!r} "  # type: ignore[attr-defined]
                         f"(exit {proc.poll()})")


def _pump(proc: subprocess.Popen) -> None:
    for line in proc.stdout:
        proc.lines.put(line)  # type: ignore[attr-defined]
    proc.lines.put(None)  # type: ignore[attr-defined]


def _start(port: int, *, via_parent: bool = False) -> tuple[subprocess.Popen, int, int]:
    """(process, server pid, firmware pid) once the firmware is calibrated and served."""
    firmware_or_skip()
    cmd = [*CLI, *SERVE.format(port=port).split()]
    if via_parent:
        cmd = [sys.executable, "-c", PARENT, *cmd]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, preexec_fn=_default_sigint)
    proc.lines, proc.seen = queue.SimpleQueue(), ""  # type: ignore[attr-defined]
    threading.Thread(target=_pump, args=(proc,), daemon=True).start()
    server_pid = int(_read_until(proc, r"^\d+\n").split()[0]) if via_parent else proc.pid
    out = _read_until(proc, "Ctrl-C to stop")
    m = re.search(rf"Crazyflie firmware \(SITL, pid (\d+)\) on udp://127\.0\.0\.1:{port}", out)
    assert m, out
    return proc, server_pid, int(m.group(1))


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_stops_server_and_firmware(sig):
    port = free_udp_port()
    proc, _, fw_pid = _start(port)
    try:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:  # cflib's scan probe
            probe.settimeout(5.0)
            probe.sendto(b"\xff", ("127.0.0.1", port))
            assert probe.recvfrom(64) == (b"\xff", ("127.0.0.1", port))
        proc.send_signal(sig)
        assert proc.wait(timeout=15) == 0
        assert "stopping" in _read_until(proc, "stopping", timeout_s=5)
        assert _gone(fw_pid)
    finally:
        proc.kill()
        proc.wait()


def test_dead_parent_stops_server_and_firmware():
    parent, server_pid, fw_pid = _start(free_udp_port(), via_parent=True)
    try:
        parent.kill()
        parent.wait()
        assert _gone(server_pid) and _gone(fw_pid)
    finally:
        for pid in (server_pid, fw_pid):
            if not _gone(pid, 0):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)


def test_missing_firmware_is_one_line():
    env = {**os.environ, "CF_SITL_FIRMWARE": "/nonexistent/cf2"}
    r = subprocess.run([*CLI, "sim", "--firmware"], env=env, capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [
        "error: no SITL firmware at /nonexistent/cf2; build it with `make sitl` "
        "(or set CF_SITL_FIRMWARE)"]


def _udp_sockets(pid: int) -> list[str]:
    """Local addresses (hex ``ADDR:PORT`` of /proc/net/udp) of the UDP sockets ``pid`` holds."""
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        with contextlib.suppress(OSError):
            link = os.readlink(f"/proc/{pid}/fd/{fd}")
            if link.startswith("socket:["):
                inodes.add(link[8:-1])
    with open(f"/proc/{pid}/net/udp") as f:
        rows = [line.split() for line in f.readlines()[1:]]
    return [row[1] for row in rows if row[9] in inodes]


def test_firmware_sockets_are_on_loopback_only_and_a_killed_server_leaves_no_firmware():
    """The firmware's own CRTP socket binds 127.0.0.1 (tools/sitl-socketlink-loopback.patch):
    upstream binds every interface and answers whoever sent last. Then the server is killed
    (one server started for both checks: each start calibrates the firmware in real time)."""
    proc, _, fw_pid = _start(free_udp_port())
    try:
        addresses = _udp_sockets(fw_pid)
        assert addresses, "the firmware holds no UDP socket"
        assert all(a.startswith("0100007F:") for a in addresses), addresses  # 127.0.0.1
    finally:
        proc.kill()  # SIGKILL: no clean-up code runs; the firmware dies with its parent
        proc.wait()
    assert _gone(fw_pid)


CLIENT, INTRUDER = 0xC1, 0x1D  # echo marks (cflib's own pings: 0x00)


def _echo_payload(mark: int, i: int) -> bytes:
    """A link echo payload shaped as cflib's ping ('<Bd'), which it parses and ignores."""
    return struct.pack("<Bd", mark, i)


def test_a_second_socket_cannot_reach_the_firmware_while_cflib_holds_the_link(caplog):
    """Another socket on the machine can neither fly the real firmware nor take its replies; the
    cflib client keeps the link, and reconnecting at once from a new port works."""
    echo, commander = crtp_header(15, 0), bytes([crtp_header(3, 0)])
    install_drivers()
    with SitlVehicle(firmware=firmware_or_skip(), port=free_udp_port()) as v:
        v.wait_ready(timeout_s=60)
        with (connect(v.uri, toc_cache=True) as scf,
              socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other):
            cf = scf.cf
            echoes: list[bytes] = []

            def on_link_packet(pk: CRTPPacket) -> None:
                if pk.channel == 0 and len(pk.data) == 9:  # echoes (channel 3: null packets)
                    echoes.append(bytes(pk.data))

            cf.add_port_callback(CRTPPort.LINKCTRL, on_link_packet)
            mine = cf.link.socket.getsockname()
            assert v.client == mine
            sent = [0]  # packets cflib sends (its own 10 Hz pings included)
            send = cf.link.send_packet
            cf.link.send_packet = lambda pk: (sent.__setitem__(0, sent[0] + 1), send(pk))
            pwm_max, to_firmware = 0, v.relayed[1]
            for i in range(20):  # the intruder: an echo, an unlock, then full thrust and roll
                other.sendto(bytes([echo]) + _echo_payload(INTRUDER, i), ("127.0.0.1", v.port))
                other.sendto(commander + struct.pack("<fffH", 0, 0, 0, 0), ("127.0.0.1", v.port))
                other.sendto(commander + struct.pack("<fffH", 20, 0, 0, 60000),
                             ("127.0.0.1", v.port))
                cf.send_packet(CRTPPacket(echo, _echo_payload(CLIENT, i)))  # keeps the link
                time.sleep(0.1)
                pwm_max = max(pwm_max, *v.peer.pwm)
            deadline = time.monotonic() + 10.0
            while _echo_payload(CLIENT, 19) not in echoes and time.monotonic() < deadline:
                time.sleep(0.05)
            assert _echo_payload(CLIENT, 19) in echoes  # the relay works for the client
            assert not [e for e in echoes if e[0] == INTRUDER]
            assert pwm_max == 0 and not any(v.peer.pwm)
            # Only cflib's packets went to the firmware, not the intruder's 60 (a margin of 5 for
            # a packet in flight when the counts were read).
            assert v.relayed[1] - to_firmware <= sent[0] + 5
            assert v.client == mine and v.foreign >= 45  # of 60 (a loaded kernel drops a few)
            other.settimeout(0.5)
            with pytest.raises(TimeoutError):  # no reply went to the intruder
                other.recv(64)
            other.settimeout(10.0)
            other.sendto(b"\xff", ("127.0.0.1", v.port))  # a scan probe is still answered
            assert other.recv(64) == b"\xff"
        # at once, from a new port: the closed client bounces
        with connect(v.uri, toc_cache=True) as scf:
            assert float(scf.cf.param.get_value("pid_rate.roll_kp")) > 0
            assert v.client == scf.cf.link.socket.getsockname()
    warnings = [r for r in caplog.records if "ignoring datagrams" in r.getMessage()]
    assert len(warnings) == 1  # logged once, counted after


@pytest.mark.parametrize("host", ["0.0.0.0", ""])
def test_a_host_others_reach_needs_allow_remote_in_one_line(host):
    r = subprocess.run([*CLI, "sim", "--firmware", "--host", host], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr.strip().splitlines() == [
        "error: --host 0.0.0.0 would let other machines fly the vehicle; pass --allow-remote "
        "to mean it, or serve 127.0.0.1"]
