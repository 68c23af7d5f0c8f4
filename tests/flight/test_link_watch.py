"""The runner watches the link and always delivers the stop setpoint before the link closes.

Known truth: the simulated vehicle's own state. A stop setpoint stops the motors without locking
the supervisor; the supervisor's watchdog (no setpoint for 2 s) stops them and locks it, so a
vehicle stopped but not locked got the stop. Silence is made by the simulator: ``drop=1`` loses
every log packet on the way down (the vehicle still hears the ground station); ``cut_link``
silences both directions. ``udp://`` flies in real time against :class:`UdpServer`.
"""

from __future__ import annotations

import threading
import time

import cflib.crtp
import numpy as np
import pytest
from click.testing import CliRunner

import groundstation.flight.link as link_mod
import groundstation.sim as gsim
from cfsession import open_session
from groundstation.cli import main
from groundstation.commands.fly import summary_lines
from groundstation.flight import fly_plan
from groundstation.flight.commander import FEED_BLIND_S
from groundstation.flight.telemetry import LINK_SILENCE_S
from groundstation.plan import Schedule, load_plan
from groundstation.sim import UdpServer
from tests.sim_crtp.helpers import free_udp_port

from .checks import check_closed_with_stop, check_fed_until_landed
from .conftest import (
    SIM_HOOK,
    SITL_HOST_SIDE,
    AfterLanding,
    backends,
    plan_variant,
    wait_for_stop,
)

BLOCKS = ("motors", "acc", "gyro")


def _safety(s):
    return [e.text for e in s.events() if e.source == "safety" and e.level in ("error", "warning")]


def _check_silence_abort(result, *, silenced_at_tick: int) -> None:
    """Link loss found by the watch: cause, events, no descent, the missing packets counted."""
    assert result.cause.startswith("link lost: no log packet for"), result.cause
    s = check_closed_with_stop(result)
    texts = _safety(s)
    assert texts[0].startswith("link lost: no log packet") and any("watchdog" in t for t in texts)
    assert "abort" not in [k.decode() for k in s["phases"].data["kind"]]  # no telemetry
    ticks = s["setpoints"].data["tick"]
    # 0.5 s of flight time at 10 Hz, plus the grace for cflib's threads and the silence's start
    assert silenced_at_tick <= ticks.max() <= silenced_at_tick + round(LINK_SILENCE_S * 10) + 4
    for name in BLOCKS:
        b = result.summary["blocks"][name]
        assert b["missing_at_end"] >= round(LINK_SILENCE_S / 0.02) - 5, (name, b)
        assert b["dropped"] >= b["missing_at_end"] and b["expected"] >= b["received"] + (
            b["missing_at_end"])
        assert b["received"] == len(s[name])


@backends(sitl=SIM_HOOK, radio=SIM_HOOK)
def test_log_silence_on_sim_is_link_loss_and_the_stop_reaches_the_vehicle(flight_uri, tmp_path):
    plan, uri = load_plan("hover-check"), flight_uri()

    def silence(k: int) -> None:
        if k == 40:  # in the hover: every log packet lost from now on, setpoints still arrive
            gsim.instance(uri).set_faults(drop=1.0)

    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=silence)
    _check_silence_abort(result, silenced_at_tick=40)
    sim = wait_for_stop(uri)
    assert not sim.vehicle.is_locked  # stopped by the stop setpoint, not by its watchdog


@backends(sitl=SITL_HOST_SIDE)
def test_failing_abort_path_still_delivers_and_records_the_stop(flight_uri, tmp_path,
                                                                  monkeypatch):
    """The plan raises, then the abort path raises too: the stop still reaches the vehicle."""
    plan, uri = load_plan("hover-check"), flight_uri()

    def broken(self, k):
        raise RuntimeError("descent broken")

    monkeypatch.setattr(Schedule, "abort_schedule", broken)

    def hook(k: int) -> None:
        if k == 40:
            raise RuntimeError("injected fault")

    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=hook)
    assert result.cause == "runner error: RuntimeError: injected fault"
    sim = wait_for_stop(uri)
    s = check_closed_with_stop(result)
    check_fed_until_landed(s, result)  # the last resort's stop kept fed too
    assert not sim.vehicle.is_locked and sim.vehicle.supervisor_state == "Landed"
    texts = _safety(s)
    assert "during the abort: runner error while stopping: RuntimeError: descent broken" in texts
    stops = [e.text for e in s.events() if e.text.startswith("stop setpoint sent")]
    assert stops == ["stop setpoint sent (last resort: runner error: RuntimeError: "
                     "injected fault)"]


# ---------------------------------------------------------------------------------- udp://



@pytest.fixture
def udp():
    cflib.crtp.init_drivers()
    server = UdpServer(port=free_udp_port(), seed=5)
    yield server
    server.close()


def _when_airborne(sim: gsim.Simulator, after_s: float, action) -> threading.Thread:
    """Run ``action()`` once the vehicle has flown ``after_s`` simulated seconds."""

    def watch() -> None:
        deadline = time.monotonic() + 30.0
        while not sim.vehicle.is_flying and time.monotonic() < deadline:
            time.sleep(0.01)
        sim.clock.sleep_until(sim.clock.now() + after_s)
        action()

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def _stopped_by_the_ground_station(sim: gsim.Simulator, timeout_s: float = 30.0) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        v = sim.vehicle
        if v.stop_count >= 1 and not any(v.motors_pwm):
            return not v.is_locked
        time.sleep(0.01)
    return False


def test_udp_simulator_silenced_mid_flight_aborts_fly_with_exit_2(udp, tmp_path):
    sim = udp.simulators[0]
    watcher = _when_airborne(sim, 1.0, sim.cut_link)  # both directions silent for good
    result = CliRunner().invoke(main, ["fly", "hover-check", "--uri", udp.uris[0],
                                       "--out", str(tmp_path)])
    watcher.join(timeout=5)
    assert result.exit_code == 2, result.output
    last = result.output.strip().splitlines()[-1]
    assert last.startswith("error: flight aborted: link lost: no log packet for") and ".h5" in last
    s = open_session(next(tmp_path.glob("*.h5")))
    assert s.closed_cleanly and _safety(s)[0].startswith("link lost: no log packet")
    assert s["setpoints"].data[-1]["thrust"] == 0
    summary = s.json_meta("summary")
    assert all(summary["blocks"][b]["missing_at_end"] > 0 for b in BLOCKS), summary["blocks"]
    # Nothing reaches the vehicle any more: its own watchdog stops and locks it (2 s of its
    # time; a generous wall deadline, the suite runs beside other work).
    deadline = time.monotonic() + 30
    while not sim.vehicle.is_locked and time.monotonic() < deadline:
        time.sleep(0.05)
    assert sim.vehicle.is_locked and not any(sim.vehicle.motors_pwm)


def test_udp_telemetry_silence_aborts_and_the_stop_reaches_the_vehicle(udp, tmp_path):
    sim = udp.simulators[0]
    plan = load_plan("hover-check")
    ticks: list[int] = []
    watcher = _when_airborne(sim, 1.0, lambda: sim.set_faults(drop=1.0))

    result = fly_plan(plan=plan, out=tmp_path, uri=udp.uris[0], tick_hook=ticks.append)
    watcher.join(timeout=5)
    s = open_session(result.path)
    silenced = int(s["setpoints"].data["tick"].max()) - round(LINK_SILENCE_S * 10) - 4
    _check_silence_abort(result, silenced_at_tick=max(silenced, 0))
    assert _stopped_by_the_ground_station(sim)


def test_udp_failing_abort_path_still_delivers_the_stop(udp, tmp_path, monkeypatch):
    sim = udp.simulators[0]

    def broken(self, k):
        raise RuntimeError("descent broken")

    monkeypatch.setattr(Schedule, "abort_schedule", broken)

    def hook(k: int) -> None:
        if k == 12:  # in the hover, from tick 10
            raise RuntimeError("injected fault")

    # hover-check with a 1 s take-off (real time), as the held-up test below
    plan = plan_variant("hover-check", **{
        "duration = 2.0                 # s\nthrust_start": "duration = 1.0\nthrust_start"})
    result = fly_plan(plan=plan, out=tmp_path, uri=udp.uris[0], tick_hook=hook)
    assert result.cause == "runner error: RuntimeError: injected fault"
    assert _stopped_by_the_ground_station(sim)
    s = check_closed_with_stop(result)
    assert any("descent broken" in t for t in _safety(s))


def _slow_close(monkeypatch, *, release: threading.Event, after_s: float) -> list[float]:
    """cflib's ``close_link`` held until ``release`` is set or ``after_s`` of wall time passed
    (a busy host joining cflib's threads, or a close that deadlocks); returns how long it took."""
    original, took = cflib.crazyflie.Crazyflie.close_link, []

    def close_link(cf) -> None:
        t0 = time.monotonic()
        release.wait(after_s)
        original(cf)
        took.append(time.monotonic() - t0)

    monkeypatch.setattr(cflib.crazyflie.Crazyflie, "close_link", close_link)
    return took


def test_a_close_slower_than_a_send_is_not_link_loss(sim_uri, tmp_path, monkeypatch):
    # the UDP driver's close joins a receiver that polls once a second: 1-2 s idle, more when
    # the host is busy; it once read "link lost: cflib did not take the link close within 1.5 s"
    took = _slow_close(monkeypatch, release=threading.Event(),
                       after_s=link_mod.SEND_TIMEOUT_S + 0.5)
    result = fly_plan(plan=load_plan("hover-check"), out=tmp_path, uri=sim_uri())
    assert took and took[0] > link_mod.SEND_TIMEOUT_S
    assert not result.aborted and result.cause == "", result.cause
    s = check_closed_with_stop(result)
    assert not [e for e in s.events() if e.source == "link" and e.level != "info"]


def test_a_close_that_never_returns_is_a_warning_after_the_stop(sim_uri, tmp_path, monkeypatch):
    release, uri = threading.Event(), sim_uri()
    _slow_close(monkeypatch, release=release, after_s=60.0)
    monkeypatch.setattr(link_mod, "CLOSE_TIMEOUT_S", 0.3)
    try:
        result = fly_plan(plan=load_plan("hover-check"), out=tmp_path, uri=uri)
    finally:
        release.set()
    assert not result.aborted and result.cause == "", result.cause  # the flight was complete
    s = check_closed_with_stop(result)  # the stop was delivered and recorded before the close
    late = [e for e in s.events() if e.source == "link" and e.level == "warning"]
    assert [e.text for e in late] == [
        "cflib did not take the link close within 0.3 s (the stop setpoint was delivered before)"]
    wait_for_stop(uri)  # and it reached the vehicle


def test_udp_a_ground_station_held_up_past_the_watchdog_aborts_without_a_burst(udp, tmp_path):
    """The runner's thread held up on a real-time link (Ctrl-Z then ``fg``, a blocked write, a
    slow listener): the vehicle went without setpoints and its watchdog levelled it (0.5 s) or
    cut its motors (2 s), and the runner then sent the missed setpoints as a burst and
    reported a complete flight, exit 0 (safety review). Now the late setpoint is a cause: the
    abort's descent starts from the moment the runner resumes, one setpoint per period, and
    the stop is delivered and recorded. (hover-check with a 1 s take-off and a 1 s descent:
    real time.)"""
    sim = udp.simulators[0]
    plan = plan_variant("hover-check", **{
        "duration = 2.0                 # s\nthrust_start": "duration = 1.0\nthrust_start",
        "descent_duration = 2.0": "descent_duration = 1.0"})
    held: list[float] = []

    def hook(k: int) -> None:
        if k == 12 and not held:  # in the hover, from tick 10
            time.sleep(0.8)  # past the 0.5 s level-out
            held.append(time.monotonic())

    class HeldInTheDescent:  # and once more at the descent's 4th setpoint
        seen = 0

        def begin(self, **_kw) -> None: ...
        def end(self, **_kw) -> None: ...

        def rows(self, *, stream, rows) -> None:
            if stream == "setpoints":
                before = self.seen
                self.seen += sum(1 for r in rows if r[6] == -1 and r[4] > 0)
                if before < 4 <= self.seen:
                    time.sleep(0.8)

    result = fly_plan(plan=plan, out=tmp_path, uri=udp.uris[0], tick_hook=hook,
                      listeners=[HeldInTheDescent()])
    assert result.aborted and result.cause.startswith("setpoint 13 is "), result.cause
    assert "s late: the ground station was held up" in result.cause
    assert _stopped_by_the_ground_station(sim)
    s = check_closed_with_stop(result)
    sp = s["setpoints"].data
    assert sp["tick"][sp["tick"] >= 0].max() == 12  # the late setpoint 13 was never sent
    after = sp[sp["host_time"] > sp["host_time"][sp["tick"] == 12][0]]
    descent = after["host_time"][after["thrust"] > 0]  # then the stop
    assert len(descent) == 10  # the 1 s descent at 10 Hz
    # from now, 0.1 s apart: 0.9 s and the 0.8 s hold (past-due deadlines sent at once: 0.2 s)
    assert descent[3] - descent[0] >= 0.2 and descent[-1] - descent[4] >= 0.35, np.diff(descent)
    assert any(e.text.startswith("descent setpoint 4 ") and "late: the rest of the descent "
               "from now" in e.text for e in s.events())


def test_a_link_lost_just_before_the_landing_stop_is_no_complete_flight(sim_uri, tmp_path):
    """The link cut after the plan's last setpoint, before the stop: the stop never reached the
    vehicle, and the loss, noticed in the file's tail, was filed as "after landing" and the
    flight reported complete, exit 0 (review). A lost link is always a cause."""
    uri = sim_uri()

    class CutAfterTheLastSetpoint:
        done = False

        def begin(self, **_kw) -> None: ...
        def end(self, **_kw) -> None: ...

        def rows(self, *, stream, rows) -> None:
            if stream == "setpoints" and not self.done and any(r[6] == 99 for r in rows):
                self.done = True
                gsim.instance(uri).cut_link()

    cut = CutAfterTheLastSetpoint()
    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri, listeners=[cut])
    assert cut.done and result.aborted and result.cause.startswith("link lost"), result.cause
    # indeed, the stop never arrived (the vehicle's own watchdog may have stopped it since: 2 s
    # of its time after the link closed, 50-100 ms of wall time flat out, a count of stop_count)
    assert gsim.instance(uri).vehicle.stop_setpoints == 0


def test_a_vehicle_locked_in_flight_is_never_reported_landed(sim_uri, tmp_path):
    """A vehicle its supervisor locked in flight (here an emergency stop; a commander watchdog
    timeout is the same): ``supervisor.info`` has the flying bit clear and the locked bit set,
    and the stop's feed read that as "the Crazyflie reports landed", the summary "fed 0.3 s
    until landed" (review, on a runner held up 2.5 s). It is reported locked, a warning."""
    uri = sim_uri()

    def hook(k: int) -> None:
        if k == 40:
            gsim.instance(uri).vehicle.write_param("stabilizer.stop", 1)

    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri, tick_hook=hook)
    assert gsim.instance(uri).vehicle.is_locked
    fed = result.summary["setpoints"]["after_stop"]
    assert fed["ended"] == "locked", fed
    s = check_closed_with_stop(result)
    assert not [e for e in s.events() if "reports landed" in e.text]
    assert any("the Crazyflie reports locked (supervisor.info 0x0044)" in t for t in _safety(s))
    assert ", fed 0." in summary_lines(result.summary)[-2] and " s: locked)" in (
        summary_lines(result.summary)[-2])


@backends(sitl=SIM_HOOK, radio=SIM_HOOK)
def test_log_silence_feeds_the_stop_blind_so_the_vehicle_is_not_left_to_lock(flight_uri,
                                                                              tmp_path):
    """Link loss found by the silence watch alone (every log packet lost, the setpoints still
    arriving): the stop's feed was skipped as after cflib's link loss, and the vehicle, still
    "flying" to its supervisor, locked 2 s later (review, on ``groundstation sim``'s UDP
    server). The stop is fed blind for the supervisor's 2 s and a margin, with a warning."""
    plan, uri = load_plan("hover-check"), flight_uri()

    def silence(k: int) -> None:
        if k == 40:
            gsim.instance(uri).set_faults(drop=1.0)

    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=silence)
    _check_silence_abort(result, silenced_at_tick=40)
    fed = result.summary["setpoints"]["after_stop"]
    assert fed["ended"] == "no telemetry" and fed["seconds"] >= FEED_BLIND_S - 0.1, fed
    sim = wait_for_stop(uri)
    # sim:// keeps the state at the close: fed through the hysteresis, it landed
    assert not sim.vehicle.is_locked and sim.vehicle.supervisor_state == "Landed"
    s = check_closed_with_stop(result)
    assert any(t.startswith(f"the stop setpoint fed {fed['setpoints']} more times") and
               "without telemetry" in t for t in _safety(s))


def test_a_link_lost_while_the_stop_is_fed_leaves_a_landed_flight_complete(sim_uri, tmp_path):
    """The link cut 1 s into the stop's feed, the motors logged at 0 after the stop: the flight
    read "ABORTED: link lost", exit 2 (review). The vehicle had the stop; the loss is an event
    after landing and the feed's end a warning."""
    uri = sim_uri()

    def cut() -> None:
        sim = gsim.instance(uri)
        sim.set_faults(cut_at=sim.vehicle.time_s + 1.0)

    late = AfterLanding(cut)
    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri, listeners=[late])
    assert late.done and not result.aborted, result.cause
    assert result.summary["setpoints"]["after_stop"]["ended"] == "link lost"
    s = check_closed_with_stop(result)
    texts = _safety(s)
    assert any(t.startswith("after landing: link lost: ") for t in texts), texts
    assert any("link lost before the Crazyflie reported landed" in t for t in texts), texts
