"""Whole flights of every shipped plan against sim:// at 20x real time, checked in the file
(hover-check also on the real firmware in the loop and over the emulated Crazyradio).

Known truth: the plan's compiled schedule (every setpoint, tick and phase), the 50 Hz log period
(20 ms firmware spacing), the plan's phase durations, and the simulator's own stop counter.
"""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.flight import fly_plan
from groundstation.plan import load_plan

from .checks import (
    check_airborne,
    check_closed_with_stop,
    check_fed_until_landed,
    check_log_blocks,
    check_log_blocks_jittery,
    check_setpoints,
)
from .conftest import BACKENDS, SIM_HOOK, SITL_COST, backends, wait_for_stop, wall_slack_s

PLANS = ["hover-check", "pitch-only", "roll-only", "yaw-only", "prbs-3axis"]
_RADIO_COST = ("the link does not depend on the plan: hover-check checks the three 50 Hz blocks "
               "and the 10 Hz setpoints over it (prbs-3axis would add 5-8 s)")


def _plan_backends():
    """Every plan on sim, hover-check on the others; the rest skipped with the reason."""
    for name in PLANS:
        for b in BACKENDS:
            skip = (None if b == "sim" or name == "hover-check"
                    else SITL_COST if b == "sitl" else _RADIO_COST)
            marks = () if skip is None else pytest.mark.skip(reason=f"{b}: {skip}")
            yield pytest.param(name, b, marks=marks)


@pytest.mark.parametrize(("name", "flight_uri"), list(_plan_backends()), indirect=["flight_uri"])
def test_shipped_plan_flies_and_records(name, flight_uri, tmp_path):
    plan, uri = load_plan(name), flight_uri()
    sitl = uri.startswith("udp://")
    result = fly_plan(plan=plan, out=tmp_path, uri=uri)
    assert not result.aborted, result.cause
    sim = wait_for_stop(uri)  # the vehicle saw the stop setpoint: motors off
    s = check_closed_with_stop(result)
    check_fed_until_landed(s, result, slack_s=wall_slack_s(uri))
    if not sitl:  # SITL: the firmware's own supervisor.info in the file said it
        assert not sim.vehicle.is_locked and sim.vehicle.supervisor_state == "Landed"
    if sitl:  # the firmware's log timer follows a loaded host's clock: jittery time stamps
        check_log_blocks_jittery(s, result)
    else:
        check_log_blocks(s, result)
        assert set(s.dropped().values()) == {0}  # no gaps in any block
    assert {"motors", "acc", "gyro", "battery"} <= set(s.dropped())
    vbat = s["battery"].values()[:, 0]  # the physics peer's battery (sitl: the pm patch)
    assert vbat.max() <= 4.15 and 3.5 < vbat.min() < vbat[0]  # sags under the motors' load
    check_airborne(s, plan)
    params = s.json_meta("params")  # read at connect, typed from the param TOC
    assert params["pid_rate"]["roll_kp"] == pytest.approx(250.0)
    assert isinstance(params["commander"]["enHighLevel"], int)
    link = s["link"].data  # cflib's latency pings, recorded as they arrive
    assert np.isfinite(link["latency_ms"]).sum() >= plan.duration / 5
    quality = link["quality"][np.isfinite(link["quality"])]
    if not sitl:  # cflib's UDP driver reports no link quality
        assert len(quality) >= plan.duration / 2 and (quality == 100.0).all()  # no drop fault
    rows = check_setpoints(s, plan, complete=True, slack_s=wall_slack_s(uri))
    assert result.summary["setpoints"]["scheduled"] == len(plan.compile())
    # Phases in order, each lasting the plan's duration on the flight clock.
    phases = s["phases"].data
    assert [n.decode() for n in phases["name"]] == [p.name for p in plan.phases]
    # Each phase marker is written as its first setpoint goes out, and each phase spans the
    # plan's number of setpoints: its duration on the deadline grid. (Send times on the in-process
    # simulation clock can slip on a busy host; the grid cannot.)
    first_ticks = np.cumsum([0] + [p.n_ticks for p in plan.phases[:-1]])
    sent = rows["host_time"][first_ticks]
    before = np.where(first_ticks > 0, rows["host_time"][np.maximum(first_ticks - 1, 0)], -np.inf)
    assert (phases["host_time"] <= sent + 1e-9).all() and (phases["host_time"] >= before).all()
    n_per_phase = np.bincount(rows["phase_id"], minlength=len(plan.phases))
    assert n_per_phase.tolist() == [p.n_ticks for p in plan.phases]
    assert n_per_phase.sum() / plan.setpoint_rate_hz == pytest.approx(plan.duration)
    # The first setpoint released the thrust lock; the motors ran during the flight.
    first = s["setpoints"].data[0]
    assert first["thrust"] == 0 and first["tick"] == -1
    motors = s["motors"].values()
    assert motors.max() > 20000
    assert s.meta["plan_name"] == plan.name and s.meta["uri"] == uri
    if not sitl:
        assert "simulated" in s.meta["firmware"] and int(s.meta["protocol_version"]) == 12
    else:  # the snapshot's commit, as the build tags it (was "NA": no tag, no version)
        assert s.meta["firmware"] == "sitl.6a4d2d00+patches", s.meta["firmware"]
    assert s.json_meta("summary")["blocks"]["gyro"]["received"] == len(s["gyro"])


@backends(sitl=SIM_HOOK, radio=SIM_HOOK)
def test_console_text_is_recorded_as_events(flight_uri, tmp_path):
    """The firmware's console lines reach the file (source "console"), whole and in order."""
    import groundstation.sim as gsim
    from cfsession import open_session

    uri = flight_uri()

    def raise_low_voltage(k: int) -> None:  # pm.lowVoltage above the battery: once the motors
        if k == 0:  # stop after landing, the firmware warns on its console
            gsim.instance(uri).vehicle.write_param("pm.lowVoltage", 4.2)

    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri, tick_hook=raise_low_voltage)
    console = [e for e in open_session(result.path).events() if e.source == "console"]
    assert [e.text for e in console if e.text.startswith("PM: Battery low (")], console
    assert all(not e.text.endswith("\n") for e in console)


@backends(sitl="real time: there is no simulation clock to hold")
def test_host_stall_freezes_simulation_time(flight_uri, tmp_path):
    """A ground-station thread starved for a second of wall time (a busy host: 20 s of flight at
    speed 20) must not become a setpoint gap on the flight clock: the simulation waits for the
    scheduler, as a faster host would have kept up. The firmware would re-lock the thrust after
    500 ms without setpoints, so a gap would also bring the vehicle down."""
    import time

    plan, uri = load_plan("hover-check"), flight_uri()

    def stall(k: int) -> None:
        if k == 40:  # hovering
            time.sleep(1.0)

    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=stall)
    assert not result.aborted, result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    check_setpoints(s, plan, complete=True)  # never more than one period (+20 ms) between two
    check_airborne(s, plan)


def test_a_firmware_without_power_management_flies_with_the_battery_check_skipped(
        sim_uri, tmp_path, monkeypatch):
    """A TOC without ``pm.vbat`` (CrazySim's SITL build without this project's pm patch): the
    take-off battery check is skipped with a warning, the flight and its file are complete;
    ``supervisor.info`` comes with the attitude, so the stop is fed until it says landed (it
    went without: fed blind)."""
    from groundstation.sim.vehicle import SimVehicle

    monkeypatch.setattr(SimVehicle, "LOG_VARIABLES", {
        k: v for k, v in SimVehicle.LOG_VARIABLES.items() if k != "pm.vbat"})
    plan, uri = load_plan("hover-check"), sim_uri()
    result = fly_plan(plan=plan, out=tmp_path, uri=uri)
    assert not result.aborted, result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    assert "battery" not in set(s.dropped())
    assert any(e.text.startswith("no pm.vbat in the log TOC") and e.level == "warning"
               for e in s.events())
    check_setpoints(s, plan, complete=True)
    assert s["attitude"].value_fields == ["roll", "pitch", "yaw", "info"]
    assert result.summary["setpoints"]["after_stop"]["ended"] == "landed"
