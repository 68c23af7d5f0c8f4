"""``groundstation sim --firmware``: the real firmware served on loopback, answering cflib's scan
probe, and no firmware process left behind after Ctrl-C, SIGTERM, a killed server or a dead
parent. Skipped when ``make sitl`` has not built the firmware."""

from __future__ import annotations

import contextlib
import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time

import pytest

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


def test_killed_server_leaves_no_firmware():
    proc, _, fw_pid = _start(free_udp_port())
    proc.kill()  # SIGKILL: no clean-up code runs; the firmware dies with its parent
    proc.wait()
    assert _gone(fw_pid)


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


def test_firmware_sockets_are_on_loopback_only():
    """The firmware's own CRTP socket binds 127.0.0.1 (tools/sitl-socketlink-loopback.patch):
    upstream binds every interface and answers whoever sent last."""
    proc, _, fw_pid = _start(free_udp_port())
    try:
        addresses = _udp_sockets(fw_pid)
        assert addresses, "the firmware holds no UDP socket"
        assert all(a.startswith("0100007F:") for a in addresses), addresses  # 127.0.0.1
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
