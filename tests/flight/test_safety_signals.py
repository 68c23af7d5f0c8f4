"""Signals during a flight: SIGINT/SIGTERM mid-excitation descend then stop, a second Ctrl-C
during the descent stops at once, Ctrl-C while connecting gives up at once (split from
``test_safety.py`` so the two halves of the real-time SITL flights run on both workers)."""

from __future__ import annotations

import os
import signal

import pytest

import groundstation.sim as gsim
from groundstation.errors import FlightAborted
from groundstation.flight import fly_plan

from .checks import (
    check_closed_with_stop,
    check_descent,
    check_fed_until_landed,
    check_setpoints,
    safety_events,
)
from .conftest import (
    SITL_HOST_SIDE,
    AfterLanding,
    backends,
    one_variant_on_sitl,
    plan_variant,
    wait_for_stop,
    wall_slack_s,
)

_SETTLE = 'kind = "hover"                 # level attitude, thrust = hover_thrust\nduration = '


def _pitch_only():
    """pitch-only with a 1 s settle instead of 3 s (SITL flies in real time); the signals
    come 2 s into its PRBS."""
    return plan_variant("pitch-only", **{f"{_SETTLE}3.0": f"{_SETTLE}1.0"})


class InTheDescent:
    """A listener that does ``action()`` once the abort's descent has streamed ``after``
    setpoints (tick -1, thrust above 0)."""

    def __init__(self, *, after: int, action) -> None:
        self.after, self.action, self.descent, self.done = after, action, 0, False

    def begin(self, **_kw) -> None: ...
    def end(self, **_kw) -> None: ...

    def rows(self, *, stream, rows) -> None:
        if stream == "setpoints":
            self.descent += sum(1 for r in rows if r[6] == -1 and r[4] > 0)
            if self.descent >= self.after and not self.done:
                self.done = True
                self.action()


def signal_in_excitation(plan, sig: int, *, after: int = 20):
    """A tick hook that sends ``sig`` to this process ``after`` ticks into the excitation."""
    excitation = next(p for p in plan.compile().phases if p.kind == "excitation")

    def hook(k: int) -> None:
        if k == excitation.start_tick + after:
            os.kill(os.getpid(), sig)

    return hook


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, *(
    getattr(signal, n) for n in ("SIGHUP", "SIGQUIT", "SIGTSTP") if hasattr(signal, n))])
def test_signal_mid_excitation_descends_then_stops(sig, flight_uri, tmp_path, request):
    """SIGQUIT (Ctrl-\\) killed the process with no stop setpoint and the file open; SIGTSTP
    (Ctrl-Z) suspended it and the vehicle's watchdog cut the motors (safety review)."""
    one_variant_on_sitl(request, first=sig == signal.SIGINT,
                        why="every signal takes one path, in the ground station")
    plan, uri = _pitch_only(), flight_uri()
    excitation = next(p for p in plan.compile().phases if p.kind == "excitation")
    before = signal.getsignal(sig)

    def hook(k: int) -> None:
        if k == excitation.start_tick + 20:
            os.kill(os.getpid(), sig)

    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=hook)
    assert signal.getsignal(sig) is before  # handlers restored
    assert result.aborted and signal.Signals(sig).name in result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    events = safety_events(s)
    assert events and signal.Signals(sig).name in events[0].text
    rows = check_setpoints(s, plan, complete=False, slack_s=wall_slack_s(uri))
    assert excitation.start_tick + 20 <= rows["tick"][-1] <= excitation.start_tick + 22
    check_descent(s, thrust_ceiling=34000, n=20, slack_s=wall_slack_s(uri))
    check_fed_until_landed(s, result, slack_s=wall_slack_s(uri))  # left unlocked
    with pytest.raises(FlightAborted, match=r"flight aborted: SIG.*session saved to"):
        result.raise_if_aborted()


def test_ctrl_c_while_connecting_gives_up_at_once(tmp_path):
    """A silent peer would hold the connect for its whole timeout; SIGINT ends it now."""
    import os
    import socket
    import threading
    import time

    from groundstation.errors import LinkError

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))  # a port that exists but never answers
        port = s.getsockname()[1]
        threading.Timer(0.5, os.kill, (os.getpid(), signal.SIGINT)).start()
        t0 = time.monotonic()
        with pytest.raises(LinkError, match="cancelled"):
            fly_plan(plan="hover-check", out=tmp_path, uri=f"udp://127.0.0.1:{port}",
                     connect_timeout_s=20.0)
    assert time.monotonic() - t0 < 5.0
    assert not list(tmp_path.glob("*.h5"))  # nothing was flown, nothing recorded


@backends(sitl=SITL_HOST_SIDE)
def test_second_signal_during_the_descent_stops_at_once(flight_uri, tmp_path):
    plan, uri = _pitch_only(), flight_uri()
    hook = signal_in_excitation(plan, signal.SIGINT)

    second = InTheDescent(after=5, action=lambda: os.kill(os.getpid(), signal.SIGINT))
    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=hook, listeners=[second])
    assert result.aborted
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    sp = s["setpoints"].data
    descent = sp[(sp["tick"] == -1) & (sp["thrust"] > 0)]
    assert 5 <= len(descent) <= 7  # of the 20 planned: stopped at the next deadline
    texts = [e.text for e in safety_events(s)]
    assert sum("during the abort" in t for t in texts) == 1, texts


def test_an_interrupt_is_honoured_from_the_start_when_launched_with_sigint_ignored():
    """A script's background job (``groundstation fly ... &``) starts with SIGINT ignored:
    the flight's handler overrode that once flying, but a ``kill -INT`` while connecting was
    lost and the whole plan was flown (first-day audit). The command restores the default
    interrupt before any work."""
    from click.testing import CliRunner

    from groundstation.cli import main

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        CliRunner().invoke(main, ["info", "--help"])
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, previous)


@pytest.mark.skipif(not hasattr(signal, "SIGHUP"), reason="POSIX signal")
def test_a_flight_started_under_nohup_outlives_the_hangup(sim_uri, tmp_path):
    """``nohup groundstation fly ...`` sets SIGHUP to be ignored so that the flight survives
    a closed terminal: it stays ignored while flying (the review found the flight's handler
    aborting it at the first hangup). (pitch-only flown whole here: 5 s of its PRBS, the
    hangup 2 s into it, and its 1 s doublet in 2 s.)"""
    plan = plan_variant("pitch-only", **{
        f"{_SETTLE}3.0": f"{_SETTLE}1.0", "duration = 25.5 ": "duration = 5.0 ",
        "duration = 5.0                 # s": "duration = 2.0                 # s"})
    uri = sim_uri()
    hook = signal_in_excitation(plan, signal.SIGHUP)

    previous = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=hook)
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGHUP, previous)
    assert not result.aborted, result.cause
    check_setpoints(check_closed_with_stop(result), plan, complete=True)


@pytest.mark.skipif(not hasattr(signal, "SIGHUP"), reason="POSIX signal")
def test_one_hangup_delivered_twice_keeps_the_descent(sim_uri, tmp_path):
    """A closed terminal can deliver SIGHUP twice (the kernel's, then the shell's to its
    jobs): that is one hangup, not an operator's second request, so the descent is flown in
    full (a second SIGINT stops it at once: the test above)."""
    plan, uri = _pitch_only(), sim_uri()
    hook = signal_in_excitation(plan, signal.SIGHUP)

    second = InTheDescent(after=3, action=lambda: os.kill(os.getpid(), signal.SIGHUP))
    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=hook, listeners=[second])
    assert second.done
    assert result.aborted and "SIGHUP" in result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    assert not any("during the abort" in e.text for e in safety_events(s))
    check_descent(s, thrust_ceiling=34000, n=20)


@pytest.mark.skipif(not hasattr(os, "fork") or not hasattr(signal, "SIGHUP"),
                    reason="POSIX terminal")
def test_a_terminal_closed_mid_flight_aborts_and_exits_2(tmp_path):
    """`fly` on a terminal that closes mid-flight (its window shut, SSH dropped): SIGHUP aborts
    with the descent and the stop, the file closes cleanly, and the exit status is 2. After
    the hang-up every write to the terminal fails (EIO); the summary's write escaped as a
    traceback and exit 1 (review)."""
    import pty
    import re
    import select
    import sys
    import time

    from cfsession import open_session

    def hovering(text: bytes) -> bool:  # the progress bar's phase column, styles removed
        return b"\rhover " in re.sub(rb"\x1b\[[0-9;?]*[A-Za-z]", b"", text)

    exe = os.path.join(os.path.dirname(sys.executable), "groundstation")
    pid, fd = pty.fork()
    if pid == 0:  # the child: fly on the pty, which is its controlling terminal
        try:
            os.execv(exe, [exe, "fly", "hover-check", "--uri", "sim://0?speed=2&seed=1",
                           "--out", str(tmp_path)])
        finally:
            os._exit(127)
    seen, deadline = b"", time.monotonic() + 60
    try:
        while not hovering(seen) and time.monotonic() < deadline:
            ready, _, _ = select.select([fd], [], [], 0.2)
            if ready:
                try:
                    seen += os.read(fd, 4096)
                except OSError:  # the child has closed the terminal: it ended
                    break
    finally:
        os.close(fd)  # the terminal closes: SIGHUP to its session
    assert hovering(seen), seen[-500:]
    waited = 0.0
    while (done := os.waitpid(pid, os.WNOHANG))[0] == 0 and waited < 60:
        time.sleep(0.1)
        waited += 0.1
    if done[0] == 0:
        os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        pytest.fail("fly did not end after its terminal closed")
    assert os.waitstatus_to_exitcode(done[1]) == 2
    [path] = tmp_path.glob("*.h5")
    s = open_session(path)
    assert s.closed_cleanly and s["setpoints"].data["thrust"][-1] == 0
    texts = [e.text for e in s.events()]
    assert "SIGHUP received" in texts and any("stop setpoint sent" in t for t in texts)


def test_a_full_disk_during_the_descent_does_not_cut_it_short(sim_uri, tmp_path, monkeypatch):
    """The disk refusing the file room during an abort's descent is an event, not a second
    cause: the descent the reserve was kept for is flown in full. As a cause it ended the
    descent like an operator's second Ctrl-C, and the stop came at hover thrust, 10 of the 20
    descent setpoints flown (review)."""
    from cfsession.writer import SessionWriter

    plan, uri = _pitch_only(), sim_uri()
    full = {"now": False}
    monkeypatch.setattr(SessionWriter, "trouble", property(
        lambda self: "disk full: no room left in the test's folder" if full["now"] else ""))
    fills = InTheDescent(after=3, action=lambda: full.update(now=True))
    result = fly_plan(plan=plan, out=tmp_path, uri=uri, listeners=[fills],
                      tick_hook=signal_in_excitation(plan, signal.SIGINT))
    assert result.aborted and result.cause == "SIGINT received"
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    check_descent(s, thrust_ceiling=34000, n=20)
    texts = [e.text for e in safety_events(s)]
    assert any(t.startswith("during the abort: disk full") for t in texts), texts


def test_a_full_disk_after_the_landing_is_no_abort(sim_uri, tmp_path, monkeypatch):
    """The disk refusing room while the file records its tail after a landed flight (the stop
    sent): an event "after landing", and the flight is not reported aborted (it was)."""
    from cfsession.writer import SessionWriter

    full = {"now": False}
    monkeypatch.setattr(SessionWriter, "trouble", property(
        lambda self: "disk full: no room left in the test's folder" if full["now"] else ""))

    class FillsAfterLanding:
        def begin(self, **_kw) -> None: ...
        def end(self, **_kw) -> None: ...

        def rows(self, *, stream, rows) -> None:
            if stream == "events" and any(b"flight complete" in bytes(r[3]) for r in rows):
                full["now"] = True

    result = fly_plan(plan="hover-check", out=tmp_path, uri=sim_uri(),
                      listeners=[FillsAfterLanding()])
    assert full["now"] and not result.aborted, result.cause
    s = check_closed_with_stop(result)
    texts = [e.text for e in safety_events(s)]
    assert texts == ["after landing: disk full: no room left in the test's folder"], texts


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="Linux's always-full device")
@pytest.mark.parametrize("json_out", [False, True])
def test_a_summary_that_finds_the_disk_full_is_one_line_after_a_whole_flight(tmp_path,
                                                                           json_out):
    """`fly ... > file` on a full disk: the flight is flown and saved whole, and the summary it
    could not write is one line naming the session and exit 2 (it was a traceback)."""
    import subprocess
    import sys

    from cfsession import open_session

    exe = os.path.join(os.path.dirname(sys.executable), "groundstation")
    with open("/dev/full", "w") as full:
        done = subprocess.run([exe, "fly", "hover-check", "--uri", "sim://0?speed=inf&seed=1",
                               "--out", str(tmp_path), *(["--json"] if json_out else [])],
                              stdout=full, stderr=subprocess.PIPE, text=True, timeout=120)
    [path] = tmp_path.glob("*.h5")
    assert done.returncode == 2
    assert done.stderr.splitlines()[-1] == (
        "error: cannot write the flight's summary to standard output (No space left on "
        f"device); the session is {path}")
    assert "Traceback" not in done.stderr
    s = open_session(path)
    assert s.closed_cleanly and s["setpoints"].data["thrust"][-1] == 0
    assert not [e.text for e in s.events() if "abort" in e.text.lower()]


@pytest.mark.parametrize("sig", [signal.SIGINT, *(getattr(signal, n) for n in ("SIGHUP",)
                                                    if hasattr(signal, n))])
def test_a_signal_after_the_landing_leaves_the_flight_complete(sig, sim_uri, tmp_path):
    """Ctrl-C in the half second the file records after the stop made a flight that had landed
    "aborted" (exit 2; safety review). It is an event now; the flight is complete. Nor does it
    end the stop's feed (a hangup did, a Ctrl-C did: the vehicle, still "flying" to its
    supervisor, locked 2 s later; review): motors-off goes on until it reports landed."""
    uri = sim_uri()
    late = AfterLanding(lambda: os.kill(os.getpid(), sig))
    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri, listeners=[late])
    assert late.done and not result.aborted, result.cause
    s = check_closed_with_stop(result)
    assert any(e.text == f"after landing: {sig.name} received" for e in s.events())
    check_fed_until_landed(s, result)
    assert not gsim.instance(uri).vehicle.is_flying  # sim:// keeps its state at the close
