"""A terminal's Ctrl-C (SIGINT to the whole process group) during ``groundstation fly
--live-id``: the flight aborts as without live identification (descent, stop, exit 2, one
line), and the identification child leaves the signal to its parent. It used to die of it
with a ``KeyboardInterrupt`` traceback from ``sysid.live._serve`` on the terminal, and the
flight's worker then logged a ``BrokenPipeError`` traceback (audit: ``pg_liveid``).

Known truth: the process group itself: the signal goes to every process in it, as a
terminal sends it; the child must be running (past its start-up, the excitation flying) when
it arrives (an update has come back), and no process of the group may outlive the
command."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from groundstation.plan import load_plan

pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").exists(),
                                reason="POSIX process groups, children found in /proc")

DEADLINE_S = 120.0  # generous: the point is that it ends cleanly, not how fast


def _children(pid: int) -> list[tuple[int, str]]:
    """``(pid, command line)`` of the live processes whose parent is ``pid``."""
    out = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmd = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        fields = stat.rsplit(")", 1)[1].split()
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append((int(entry.name), cmd))
    return out


def _group_alive(pgid: int) -> bool:
    """Whether any process (an orphan not yet reaped too) is still in group ``pgid``."""
    try:
        os.killpg(pgid, 0)
    except ProcessLookupError:
        return False
    return True


def _wait(what: str, cond, proc: subprocess.Popen, err: Path, *, ended_ok: bool = False
          ) -> None:
    deadline = time.monotonic() + DEADLINE_S
    while not cond():
        if not ended_ok and proc.poll() is not None:
            pytest.fail(f"fly ended before {what}: {err.read_text()}")
        if time.monotonic() > deadline:
            pytest.fail(f"no {what} within {DEADLINE_S:g} s: {err.read_text()}")
        time.sleep(0.05)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGHUP],  # SIGTERM: SIGINT's path
                         ids=lambda s: signal.Signals(s).name)
def test_a_signal_to_the_process_group_aborts_without_the_childs_traceback(tmp_path, sig):
    exe = Path(sys.executable).with_name("groundstation")
    cmd = [str(exe)] if exe.exists() else [sys.executable, "-c",
                                           "from groundstation.cli import main; main()"]
    out, err = tmp_path / "stdout", tmp_path / "stderr"
    # roll-only with small horizons: its first update comes back 5 s of flight into the PRBS
    # instead of 15 s (the thesis' past 60, future 17 need 615 samples)
    plan = tmp_path / "roll-only.toml"
    plan.write_text(load_plan("roll-only").text + "\n[live_id]\norder = 4\npast = 15\n"
                    "future = 8\n", encoding="utf-8")
    with out.open("wb") as fo, err.open("wb") as fe:
        proc = subprocess.Popen([*cmd, "fly", str(plan), "--uri", "sim://0?speed=5&seed=1",
                                 "--out", str(tmp_path / "sessions"), "--live-id"],
                                stdin=subprocess.DEVNULL, stdout=fo, stderr=fe,
                                start_new_session=True)  # its own group, as a terminal job
    try:
        live: list[int] = []

        def worker_runs() -> bool:
            live[:] = [p for p, c in _children(proc.pid) if "sysid.live" in c]
            return bool(live) and " upd (" in err.read_text()  # an update in the progress

        _wait("live identification update", worker_runs, proc, err)
        os.killpg(proc.pid, sig)
        proc.wait(timeout=DEADLINE_S)
        _wait("end of the process group", lambda: not _group_alive(proc.pid), proc, err,
              ended_ok=True)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    stderr = err.read_text()
    name = signal.Signals(sig).name
    assert proc.returncode == 2, stderr  # docs/flying.md: an aborted flight exits 2
    assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
    assert "live id worker failed" not in stderr, stderr
    assert stderr.strip().splitlines()[-1].startswith(f"error: flight aborted: {name} received;")
    # the child kept serving: the abort's final update (and every other one) came back
    assert re.search(r"live id [1-9]\d* updates \(\d+ skipped, 0 failed\)", out.read_text())
