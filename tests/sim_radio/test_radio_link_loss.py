"""A radio that stops answering mid-flight is link loss: the vehicle flies out of range or is
switched off, every transfer then fails, and the flight aborts with the cause recorded, the
session readable and (out of range) the vehicle stopped by its own watchdog.

Known truth: the emulated vehicle's state (``in_range``, its supervisor's lock and motors), the
plan's length, and ``fly``'s exit code for an aborted flight (2)."""

from __future__ import annotations

import threading
import time

from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main
from groundstation.flight import fly_plan
from groundstation.plan import load_plan
from groundstation.sim.crazyradio_usb import installed_bus

from ..flight.checks import check_closed_with_stop
from .backend import URI


def _safety(s) -> list[str]:
    return [e.text for e in s.events() if e.source == "safety" and e.level in ("error", "warning")]


def test_out_of_range_is_link_loss_and_the_watchdog_stops_the_vehicle(bus, tmp_path):
    plan = load_plan("hover-check")
    vehicle = bus.vehicles[0]

    def fly_away(k: int) -> None:
        if k == 40:  # hovering
            vehicle.leave_range()

    result = fly_plan(plan=plan, out=tmp_path, uri=URI, tick_hook=fly_away)
    assert result.aborted and result.cause.startswith("link lost"), result.cause
    stats = bus.dongles[0].stats
    assert stats.ok[-1] is False and stats.failed >= 1  # the dongle's last transfers: no ack
    s = check_closed_with_stop(result)
    texts = _safety(s)
    assert texts[0].startswith("link lost") and any("watchdog" in t for t in texts)
    assert "abort" not in [k.decode() for k in s["phases"].data["kind"]]  # no link: no descent
    assert 40 <= s["setpoints"].data["tick"].max() < len(plan.compile()) - 1
    # nothing reaches the vehicle: its supervisor stops and locks it (2 s of its own time;
    # the wall deadline only guards a stuck test)
    v = vehicle.sim.vehicle
    deadline = time.monotonic() + 30.0
    while not (v.is_locked and not any(v.motors_pwm)) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert v.is_locked and not any(v.motors_pwm)


def _switch_off_once_airborne(after_s: float) -> threading.Thread:
    """Power the emulated vehicle off ``after_s`` simulated seconds after it took off (the bus
    is the one ``fly --emulated-radio`` installs)."""

    def watch() -> None:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline:
            bus = installed_bus()
            sim = bus.vehicles[0].sim if bus is not None else None
            if sim is not None and sim.vehicle.is_flying:
                start = sim.vehicle.time_s
                while sim.vehicle.time_s < start + after_s and time.monotonic() < deadline:
                    time.sleep(0.002)  # polled, not slept on its clock: that would pace it
                bus.vehicles[0].power_off()
                return
            time.sleep(0.002)

    thread = threading.Thread(target=watch, daemon=True)
    thread.start()
    return thread


def test_vehicle_switched_off_aborts_fly_with_exit_2(tmp_path):
    watcher = _switch_off_once_airborne(1.0)
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", URI, "--emulated-radio",
                                    "--emulated-radio-speed", "20", "--out", str(tmp_path)])
    watcher.join(timeout=5)
    assert not watcher.is_alive()
    assert res.exit_code == 2, res.output
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("error: flight aborted: link lost") and ".h5" in last
    s = open_session(next(tmp_path.glob("*.h5")))
    assert s.closed_cleanly and not s.problems
    assert _safety(s)[0].startswith("link lost")
    assert s["setpoints"].data[-1]["thrust"] == 0  # the stop is recorded (it reached no one)
    summary = s.json_meta("summary")
    assert all(summary["blocks"][b]["missing_at_end"] > 0 for b in ("motors", "acc", "gyro"))
    assert installed_bus() is None  # fly took its emulated dongle off the bus again
