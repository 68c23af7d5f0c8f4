"""Each safety path ends with the motors stopped on the simulated vehicle, a readable file and the
cause recorded as an event from source "safety".

Known truth: the simulator's own stop counter and motor outputs, the plan's abort policy
(``descend``: 2 s at <= 34000 PWM, level; ``stop``: nothing before the stop setpoint) and the
10 Hz grid (no gap longer than one period while flying).
"""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

import groundstation.sim as gsim
from groundstation.errors import LinkError
from groundstation.flight import RateLimits, fly_plan
from groundstation.plan import load_plan

from .checks import (
    check_closed_with_stop,
    check_descent,
    check_fed_until_landed,
    safety_events,
)
from .conftest import (
    SIM_HOOK,
    SITL_AS_SIGNAL,
    SITL_HOST_SIDE,
    backends,
    one_variant_on_sitl,
    plan_variant,
    wait_for_stop,
    wall_slack_s,
)


@backends(sitl=SIM_HOOK, radio=f"{SIM_HOOK}; a radio that stops answering (out of range, "
         "powered off, unplugged) is tests/sim_radio/test_radio_link_loss.py")
def test_link_cut_records_the_loss_and_the_watchdog_stops_the_motors(flight_uri, tmp_path):
    plan, uri = load_plan("hover-check"), flight_uri()

    def cut(k: int) -> None:
        if k == 40:  # in the hover: the simulated radio goes silent for good
            gsim.instance(uri).cut_link()

    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=cut)
    assert result.aborted and result.cause.startswith("link lost")
    sim = wait_for_stop(uri)  # supervisor: no setpoint for 2 s -> motors off, locked
    assert sim.vehicle.is_locked
    s = check_closed_with_stop(result)
    assert safety_events(s)[0].text.startswith("link lost")
    assert any("watchdog" in e.text for e in s.events())
    assert "abort" not in [k.decode() for k in s["phases"].data["kind"]]  # no link: no descent
    # Detection goes through the simulator's thread and cflib's: a few sends go into the void.
    assert 40 <= s["setpoints"].data["tick"].max() < len(plan.compile()) - 1


@backends(sitl=SITL_AS_SIGNAL)
def test_exception_in_the_runner_aborts_safely(flight_uri, tmp_path):
    plan, uri = load_plan("hover-check"), flight_uri()

    def hook(k: int) -> None:
        if k == 40:
            raise RuntimeError("injected fault")

    result = fly_plan(plan=plan, out=tmp_path, uri=uri, tick_hook=hook)
    assert result.cause == "runner error: RuntimeError: injected fault"
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    assert "injected fault" in safety_events(s)[0].text
    assert s["setpoints"].data["tick"].max() == 39
    check_descent(s, thrust_ceiling=34000, n=20, slack_s=wall_slack_s(uri))
    check_fed_until_landed(s, result, slack_s=wall_slack_s(uri))  # left unlocked
    # from the hover (39000, capped at the plan's 34000): the runner error lost the tick, and
    # the descent was computed for tick 0, the take-off's 20000 (review)
    sp = s["setpoints"].data
    assert set(sp["thrust"][(sp["tick"] == -1) & (sp["thrust"] > 0)]) == {34000}


def _battery_of(uri: str):
    """The battery model behind ``uri`` (the simulation's, or the SITL physics peer's)."""
    if uri.startswith("udp://"):
        from ..sitl import backend

        return backend.vehicle(uri).peer.battery
    return gsim.instance(uri).vehicle.battery


@backends(radio="the battery and its watch are the simulation's and the ground station's, "
                "as on sim; the emulated radio adds nothing to them")
def test_a_battery_running_out_in_flight_lands_before_the_firmware_shuts_down(flight_uri,
                                                                            tmp_path):
    """Under load the battery sags below pm.lowVoltage (3.2 V); after 5 s of that the firmware
    reports low power, and 5 s below 3.0 V it shuts down in the air: the flight lands on the
    first report (it flew on, the take-off check being the only one: review)."""
    uri = flight_uri()

    def drain(k: int) -> None:
        if k == 5:  # 0.5 s into the take-off: a third of the charge left, 3.35 V at rest
            _battery_of(uri).charge = 0.3

    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri, tick_hook=drain)
    assert result.cause.startswith("battery low in flight: the Crazyflie's power management "
                                   "reports low power (pm.state 3"), result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    assert safety_events(s)[-1].text.startswith("battery low in flight")
    battery = s["battery"]
    low = battery.time[battery.data["state"] == 3]
    assert low.size and battery.data["vbat"][battery.time < low[0]][-1] < 3.2
    # the firmware's rule, not the sag's first sample: 5 s below 3.2 V before it says so
    assert low[0] - s["setpoints"].time[s["setpoints"].data["tick"] == 5][0] >= 5.0
    check_descent(s, thrust_ceiling=34000, n=20, slack_s=wall_slack_s(uri))


def test_a_vehicle_reporting_low_power_refuses_to_take_off(sim_uri, tmp_path):
    """A battery that read low for 5 s at rest (3.10 V, above a plan's min_vbat of 3.0): the
    firmware's own judgement refuses the take-off, whatever min_vbat allows."""
    import time

    uri = sim_uri()
    sim = gsim.simulator_for_uri(uri)  # powered on before anything connects
    sim.vehicle.battery.charge = 0.1
    deadline = time.monotonic() + 60.0
    while not sim.vehicle.low_power and time.monotonic() < deadline:
        time.sleep(0.05)
    assert sim.vehicle.low_power
    plan = plan_variant("hover-check", **{"min_vbat = 3.8 ": "min_vbat = 3.0 "})
    result = fly_plan(plan=plan, out=tmp_path, uri=uri)
    assert result.cause.startswith("the Crazyflie reports low power (pm.state 3: battery 3.1"), \
        result.cause
    assert result.cause.endswith("refusing to take off; charge or swap the battery")
    s = check_closed_with_stop(result)
    assert (s["setpoints"].data["thrust"] == 0).all() and s["motors"].values().max() == 0


def test_low_power_during_the_planned_landing_lands_as_planned(sim_uri, tmp_path):
    """The report arriving in the landing phase: the vehicle is already landing, so no abort
    (the session would read "aborted" for a plan flown through), one warning event."""
    uri = sim_uri()

    def drain(k: int) -> None:
        if k == 25:  # low power 5 s later: in the landing (7-10 s)
            _battery_of(uri).charge = 0.3

    result = fly_plan(plan="hover-check", out=tmp_path, uri=uri, tick_hook=drain)
    assert not result.aborted, result.cause
    s = check_closed_with_stop(result)
    assert any(e.text == "the Crazyflie reports low power (pm.state 3); it is landing as planned"
               for e in safety_events(s))
    assert (s["battery"].data["state"] == 3).any()


def test_stop_policy_stops_at_once(flight_uri, tmp_path):
    plan = plan_variant("hover-check", **{'on_abort = "descend"': 'on_abort = "stop"'})
    uri = flight_uri()
    result = fly_plan(plan=plan, out=tmp_path, uri=uri,
                      tick_hook=lambda k: k == 30 and os.kill(os.getpid(), signal.SIGINT))
    assert "SIGINT" in result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    sp = s["setpoints"].data
    assert sp["tick"].max() <= 31 and (sp[sp["tick"] == -1]["thrust"][1:] == 0).all()
    assert np.diff(sp["host_time"][-2:])[0] <= 0.2 + wall_slack_s(uri)  # within a period


@pytest.mark.parametrize("where", ["plan", "api"])
def test_rate_limit_violation_aborts(where, flight_uri, tmp_path, request):
    one_variant_on_sitl(request, first=where == "plan",
                        why="a limit from the plan or the API is checked alike, in the ground "
                            "station")
    # Thrust above the simulated vehicle's hover (39153 PWM) so it is surely airborne:
    # a vehicle resting on the ground has no body rates.
    # A 1 s settle instead of 3 s (SITL flies in real time): the PRBS trips the limit at once.
    settle = 'kind = "hover"                 # level attitude, thrust = hover_thrust\nduration = '
    edits = {"hover_thrust = 39000": "hover_thrust = 40500", f"{settle}3.0": f"{settle}1.0"}
    if where == "plan":  # the plan's [safety] max_rate_deg_s
        edits['[safety]\n'] = '[safety]\nmax_rate_deg_s = 10.0\n'
    plan = plan_variant("roll-only", **edits)
    uri = flight_uri()
    limits = RateLimits(max_rate_deg_s=10.0, samples=2) if where == "api" else None
    result = fly_plan(plan=plan, out=tmp_path, uri=uri, limits=limits)
    assert result.cause.startswith("limit: gyro.") and "beyond 10 deg/s" in result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    gyro = s["gyro"].values()
    assert (np.abs(gyro) > 10.0).any(axis=1).sum() >= 2  # the file shows the violation
    assert 0 <= s["setpoints"].data["tick"].max() < len(plan.compile()) - 1  # cut short
    check_descent(s, thrust_ceiling=34000, n=20, slack_s=wall_slack_s(uri))


def test_low_battery_refuses_to_take_off(flight_uri, tmp_path):
    plan = plan_variant("hover-check", **{"min_vbat = 3.8 ": "min_vbat = 4.2 "})
    uri = flight_uri()  # the simulated battery is at most 4.15 V
    result = fly_plan(plan=plan, out=tmp_path, uri=uri)
    assert result.cause.startswith("battery 4.1") and "refusing to take off" in result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    assert (s["setpoints"].data["thrust"] == 0).all() and s["motors"].values().max() == 0
    assert s["battery"].values()[0, 0] < 4.2


def test_a_locked_vehicle_refuses_to_take_off(sim_uri, tmp_path):
    """A vehicle its supervisor locked (here: the commander watchdog after a link cut in the
    hover) runs no motors until restarted. A second flight "flew" it with its motors at 0,
    every setpoint sent, exit 0 (SITL: after any flight, before the stop was fed until
    landed; first-day review)."""
    uri = sim_uri()

    def cut(k: int) -> None:
        if k == 40:
            gsim.instance(uri).cut_link()

    fly_plan(plan="hover-check", out=tmp_path / "first", uri=uri, tick_hook=cut)
    sim = wait_for_stop(uri)
    assert sim.vehicle.is_locked
    result = fly_plan(plan="hover-check", out=tmp_path / "second", uri=uri)
    assert result.aborted and result.cause.startswith("the Crazyflie is locked (supervisor.info")
    assert "refusing to take off; power-cycle it" in result.cause
    s = check_closed_with_stop(result)
    assert (s["setpoints"].data["thrust"] == 0).all()
    assert s["battery"].data["info"][0] & 0x40


def test_a_vehicle_that_does_not_arm_itself_is_refused_unless_fly_arm(sim_uri, tmp_path):
    """A Crazyflie that does not arm itself (the Brushless; ``autoarm=0``) runs no motors until
    armed: like a locked one, it "flew" a plan with its motors at 0, exit 0. It is refused,
    nothing flown, unless ``arm`` (``fly --arm``): then armed and flown."""
    refused = fly_plan(plan="hover-check", out=tmp_path / "refused", uri=sim_uri(autoarm=0))
    assert refused.aborted and refused.cause.startswith("the Crazyflie is not armed (")
    assert "fly --arm arms it before take-off" in refused.cause
    s = check_closed_with_stop(refused)
    assert (s["setpoints"].data["thrust"] == 0).all() and not s["battery"].data["info"][0] & 2
    uri = sim_uri(autoarm=0)
    flown = fly_plan(plan="hover-check", out=tmp_path / "armed", uri=uri, arm=True)
    assert not flown.aborted, flown.cause
    s = check_closed_with_stop(flown)
    assert [e.text for e in s.events() if e.text.startswith(("arming", "armed"))] == [
        "arming requested (fly --arm)", "armed (supervisor.info 0x000a)"]
    assert s["motors"].values().max() > 20000  # it flew
    check_fed_until_landed(s, flown)


def test_fly_arm_without_supervisor_info_requests_arming_and_says_it_cannot_be_confirmed(
        sim_uri, tmp_path, monkeypatch, caplog):
    """``fly --arm`` on a firmware whose log TOC has no ``supervisor.info`` skipped the arming
    request and said nothing: a vehicle that does not arm itself "flew" the plan with its
    motors at 0. The request is sent all the same, and a warning (logged and recorded) says
    the arming cannot be confirmed and the flight goes on."""
    from groundstation.sim.vehicle import SimVehicle

    monkeypatch.setattr(SimVehicle, "LOG_VARIABLES", {
        k: v for k, v in SimVehicle.LOG_VARIABLES.items() if k != "supervisor.info"})
    with caplog.at_level("WARNING", logger="groundstation"):
        result = fly_plan(plan="hover-check", out=tmp_path, uri=sim_uri(autoarm=0), arm=True)
    assert not result.aborted, result.cause
    s = check_closed_with_stop(result)
    assert "info" not in s["battery"].value_fields
    (warned,) = [e for e in s.events() if "fly --arm" in e.text]
    assert warned.level == "warning" and warned.text.startswith(
        "fly --arm: no supervisor.info in the log TOC"), warned.text
    assert "cannot be confirmed; flying on" in warned.text
    assert [r.getMessage() for r in caplog.records if r.levelname == "WARNING"
            and "fly --arm" in r.getMessage()] == [f"runner: {warned.text}"]
    assert s["motors"].values().max() > 20000  # armed: it flew


def test_a_vehicle_that_cannot_be_armed_is_refused_at_once_for_what_it_is(
        sim_uri, tmp_path, monkeypatch):
    """A crashed Crazyflie (``supervisor.info`` bit 7; the firmware disarmed it and takes no
    arming request until a crash recovery) was told "it does not arm itself ... fly --arm
    arms it"; with ``--arm`` the request was dropped and the runner waited 2 s for "did not
    arm". Bit 0 (can be armed) clear: refused at once, no request, the crash named."""
    from groundstation.sim.vehicle import SimVehicle

    monkeypatch.setattr(SimVehicle, "supervisor_info", lambda self: 0x0084)  # crashed, auto-arm
    for arm in (False, True):
        result = fly_plan(plan="hover-check", out=tmp_path / str(arm), uri=sim_uri(), arm=arm)
        assert result.cause.startswith("the Crazyflie is not armed and cannot be armed "
                                       "(supervisor.info 0x0084): crashed"), result.cause
        s = check_closed_with_stop(result)
        assert not [e for e in s.events() if e.text.startswith("arming requested")]
        assert (s["setpoints"].data["thrust"] == 0).all()


def test_a_vehicle_that_locks_while_arming_is_refused_as_locked(sim_uri, tmp_path,
                                                                monkeypatch):
    """A vehicle that locked during ``--arm``'s wait (an emergency stop here) was reported
    "did not arm within 2 s" after the whole wait. It is refused as locked, at its first
    report."""
    from groundstation.sim.vehicle import SimVehicle

    monkeypatch.setattr(SimVehicle, "arm", lambda self, *, armed: self.write_param(
        "stabilizer.stop", 1))
    result = fly_plan(plan="hover-check", out=tmp_path, uri=sim_uri(autoarm=0), arm=True)
    assert result.cause.startswith("the Crazyflie locked while arming (supervisor.info "
                                   "0x0040)"), result.cause
    s = check_closed_with_stop(result)
    (asked,) = [e.t for e in s.events() if e.text == "arming requested (fly --arm)"]
    (refused,) = [e.t for e in s.events() if e.text.startswith("the Crazyflie locked")]
    assert refused - asked < 1.0  # the next battery report, not the end of the 2 s wait


class _Listener:
    def __init__(self, fail_at: int | None = None) -> None:
        self.calls, self.fail_at, self.ended = 0, fail_at, None

    def begin(self, *, streams, metadata) -> None:
        self.streams = [s.name for s in streams]

    def rows(self, stream, rows) -> None:
        self.calls += 1
        if self.calls == self.fail_at:
            raise ValueError("listener bug")

    def end(self, *, summary) -> None:
        self.ended = summary


@backends(sitl=SITL_HOST_SIDE)
def test_failing_listener_is_dropped_and_the_flight_goes_on(flight_uri, tmp_path):
    bad, good = _Listener(fail_at=40), _Listener()
    # a 2 s hover and a 1 s landing: 50 setpoints (SITL flies in real time); the listener
    # fails at its 40th call
    plan = plan_variant("hover-check", **{"duration = 5.0 ": "duration = 2.0 ",
                                          "duration = 3.0 ": "duration = 1.0 "})
    uri = flight_uri()
    result = fly_plan(plan=plan, out=tmp_path, uri=uri, listeners=[bad, good])
    assert not result.aborted
    assert bad.ended is None and good.ended is not None and bad.calls == 40
    assert good.ended["setpoints"]["scheduled"] == len(plan.compile())
    s = check_closed_with_stop(result)
    assert any("listener dropped" in e.text and e.level == "error" for e in s.events())
    assert len(s["setpoints"].data[s["setpoints"].data["tick"] >= 0]) == len(plan.compile())


def test_unreachable_uri_is_a_one_line_link_error(tmp_path):
    with pytest.raises(LinkError, match=r"^cannot connect to nosuch://0: .*groundstation scan"):
        fly_plan(plan="hover-check", out=tmp_path, uri="nosuch://0", connect_timeout_s=1.0)
    assert not list(tmp_path.iterdir())  # nothing flown, no file
