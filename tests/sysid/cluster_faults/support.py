"""What the Dask fault tests share: the commands run with short timeouts, a listener
that never answers, the scheduler stopped (SIGSTOP). Everything listens on 127.0.0.1."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from sysid.cluster import CONNECT_ENV, WORKER_WAIT_ENV

ROOT = Path(__file__).resolve().parents[3]
#: The connect timeout the commands get here, and the most any fault may take to be reported
#: (process start-up included, on a loaded machine).
CONNECT_S = 2.0
DEADLINE_S = 40.0


# ---------------------------------------------------------------------------------- helpers
class Listener:
    """A TCP listener on 127.0.0.1 that accepts every connection and keeps it open, sending
    ``greeting`` (if any) and then nothing."""

    def __init__(self, greeting: bytes = b"") -> None:
        self.sock = socket.socket()
        self.sock.bind(("127.0.0.1", 0))
        self.sock.listen()
        self.address = f"tcp://127.0.0.1:{self.sock.getsockname()[1]}"
        self.greeting, self.conns = greeting, []
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    def _serve(self) -> None:
        while True:
            try:
                conn, _ = self.sock.accept()
            except OSError:  # closed
                return
            self.conns.append(conn)
            if self.greeting:
                conn.sendall(self.greeting)

    def close(self) -> None:
        self.sock.close()
        for c in self.conns:
            c.close()




def env() -> dict[str, str]:
    return {**os.environ, CONNECT_ENV: str(CONNECT_S), WORKER_WAIT_ENV: "2",
            "PYTHONPATH": str(ROOT)}


def run_sysid(*args: object) -> tuple[subprocess.CompletedProcess[str], float]:
    """Run the ``sysid`` command; (its result, seconds it took)."""
    t0 = time.monotonic()
    proc = subprocess.run([sys.executable, "-c", "from sysid.cli import main; main()",
                           *map(str, args)], capture_output=True, text=True, timeout=DEADLINE_S,
                          env=env(), cwd=ROOT)
    return proc, time.monotonic() - t0


def clean(stderr: str) -> list[str]:
    """stderr's lines, checked to hold no traceback."""
    assert "Traceback" not in stderr and "Error:" not in stderr.replace("error:", ""), stderr
    return stderr.strip().splitlines()


def cli(*args: object) -> tuple[Any, float]:
    """Run the ``sysid`` command in this process (so a test can patch what it calls); (its
    click result, seconds it took). A command still running after :data:`DEADLINE_S` fails
    the test (its thread is left to the fixtures' teardown)."""
    from click.testing import CliRunner

    from sysid.cli import main

    out: list[Any] = []
    t0 = time.monotonic()
    runner = threading.Thread(target=lambda: out.append(
        CliRunner().invoke(main, [str(a) for a in args])), daemon=True)
    runner.start()
    runner.join(DEADLINE_S)
    if not out:
        pytest.fail(f"sysid {' '.join(map(str, args))}: still running after {DEADLINE_S:g} s")
    return out[0], time.monotonic() - t0


def sweep_args(session: Path, address: str) -> list[object]:
    return ["sweep", session, "--pasts", "20,30", "--futures", "10", "--orders", "4",
            "--scheduler", address]



def summary(out: Path) -> list[str]:
    return [r["group"] for r in json.loads((out / "summary.json").read_text())]



def stop(server: subprocess.Popen[str]) -> None:
    """The scheduler's process stops (SIGSTOP): its connections stay open and the system still
    accepts new ones, but nothing answers (a hung scheduler; the fixture kills it). Returns
    once every thread of it is stopped: the signal is delivered asynchronously, and on a busy
    host a thread still running answered one more request (the dashboard's, seen once in two
    runs beside a second test run)."""
    os.kill(server.pid, signal.SIGSTOP)
    deadline = time.monotonic() + 30.0
    tasks = Path(f"/proc/{server.pid}/task")
    while tasks.is_dir() and time.monotonic() < deadline:
        states = []
        for stat in tasks.glob("*/stat"):
            with contextlib.suppress(OSError):  # a thread that ended meanwhile
                states.append(stat.read_text().rsplit(")", 1)[1].split()[0])
        if states and all(state in "Tt" for state in states):
            return
        time.sleep(0.005)

