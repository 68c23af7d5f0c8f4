"""A real-time flight against the UDP simulator: setpoint jitter, lost rows, ground-station CPU.

The simulator runs in its own process (``groundstation sim --port P``), so this process is the
ground station alone: cflib, the runner and the recorder. It flies ``hover-check`` (10 s) and
prints each figure as a ratio to its target (issue 5, item 7); ratio <= 1 passes:

* setpoint period jitter :math:`|t_{k+1} - t_k - 0.1\\,\\mathrm{s}|`, p99 on the monotonic clock,
  target < 2 ms;
* log packets cflib delivered minus rows in the session file, target 0;
* CPU of this process, ``time.process_time()`` over wall time during the flight, target < 10 %
  of one core.

The baseline measured in the same run is the CPU of an idle connection (cflib connected, the same
log blocks streaming, no runner), so the runner's own share shows too.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from cfsession import open_session
from groundstation.flight import fly_plan
from groundstation.flight.clock import MonotonicClock
from groundstation.flight.link import BATTERY_BLOCK, BLOCK_PERIOD_S, FLIGHT_BLOCKS, open_link

JITTER_P99_MS = 2.0
CPU_SHARE = 0.10
PLAN = os.environ.get("BENCH_FLIGHT_PLAN", "prbs-3axis")  # 1123 setpoints: a meaningful p99


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _start_sim(port: int) -> subprocess.Popen:
    exe = Path(sys.executable).with_name("groundstation")
    proc = subprocess.Popen([str(exe), "sim", "--port", str(port)], stdout=subprocess.PIPE,
                            stderr=subprocess.DEVNULL, text=True)
    line = proc.stdout.readline() if proc.stdout else ""
    if "simulated Crazyflie" not in line:
        proc.kill()
        raise RuntimeError(f"the UDP simulator did not start: {line!r}")
    return proc


def _idle_cpu(uri: str, seconds: float = 5.0) -> float:
    """CPU share of a connection with the flight's log blocks streaming and nothing else."""
    rows: list[tuple] = []
    link = open_link(uri=uri, clock=MonotonicClock(), post=rows.append, timeout_s=10)
    try:
        blocks = [*link.plan_blocks(blocks=FLIGHT_BLOCKS, period_s=BLOCK_PERIOD_S),
                  *link.plan_blocks(blocks={BATTERY_BLOCK[0]: BATTERY_BLOCK[1]},
                                    period_s=BATTERY_BLOCK[2])]
        link.start_blocks(blocks)
        c0, w0 = time.process_time(), time.monotonic()
        time.sleep(seconds)
        return (time.process_time() - c0) / (time.monotonic() - w0)
    finally:
        link.close()


def _bare_jitter_ms(n: int = 100, period_s: float = 0.1) -> np.ndarray:
    """Baseline: period jitter of bare deadline sleeps on this machine now (what the OS and
    the interpreter allow), same definition and switch interval as the flight's."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(0.0005)
    try:
        clock = MonotonicClock()
        t0 = clock.now() + period_s
        sent = []
        for k in range(n):
            clock.sleep_until(t0 + k * period_s)
            sent.append(clock.now())
    finally:
        sys.setswitchinterval(previous)
    return np.abs(np.diff(sent) - period_s) * 1000.0


def main() -> int:
    bare = _bare_jitter_ms()
    port = _free_port()
    proc = _start_sim(port)
    uri = f"udp://127.0.0.1:{port}"
    try:
        idle = _idle_cpu(uri)
        with tempfile.TemporaryDirectory(prefix="bench-flight-") as out:
            c0, w0 = time.process_time(), time.monotonic()
            result = fly_plan(plan=PLAN, out=out, uri=uri)
            cpu = (time.process_time() - c0) / (time.monotonic() - w0)
            s = open_session(result.path)
            missing = {name: b["received"] - len(s[name])
                       for name, b in result.summary["blocks"].items()}
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    sp = result.summary["setpoints"]
    jitter = sp["jitter_ms"]
    print(f"flight {PLAN} on {uri}: {result.summary['duration_s']:.1f} s, "
          f"{sp['sent']} setpoints, aborted: {result.cause or 'no'}")
    print(f"setpoint period jitter p50 {jitter['p50']:.3f} ms, p99 {jitter['p99']:.3f} ms, "
          f"max {jitter['max']:.3f} ms; p99 / target {JITTER_P99_MS} ms = "
          f"{jitter['p99'] / JITTER_P99_MS:.2f}")
    bare_p99 = float(np.percentile(bare, 99))
    print(f"baseline: bare deadline sleeps on this machine now: p50 {np.median(bare):.3f} ms, "
          f"p99 {bare_p99:.3f} ms; flight p99 / bare p99 = {jitter['p99'] / bare_p99:.2f} "
          f"(load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)")
    for name, b in result.summary["blocks"].items():
        print(f"log {name}: {b['received']} delivered by cflib, {b['received'] - missing[name]} "
              f"rows in the file, {b['dropped']} dropped on the link")
    print(f"rows missing from the file: {sum(missing.values())} (target 0)")
    print(f"ground-station CPU {100 * cpu:.1f} % of one core; / target {100 * CPU_SHARE:.0f} % "
          f"= {cpu / CPU_SHARE:.2f}; baseline idle connection {100 * idle:.1f} % "
          f"(flight / idle = {cpu / max(idle, 1e-9):.2f})")
    ok = (not result.aborted and jitter["p99"] < JITTER_P99_MS
          and not any(missing.values()) and cpu < CPU_SHARE)
    return 0 if ok and np.isfinite(cpu) else 1


if __name__ == "__main__":
    sys.exit(main())
