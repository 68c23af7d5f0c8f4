"""What every recorded flight must satisfy (shared by the sim tests and hw_tests)."""

from __future__ import annotations

import numpy as np

from cfsession import Session, open_session
from groundstation.flight import FlightResult
from groundstation.plan import Plan

BLOCKS = ("motors", "acc", "gyro")


def check_airborne(s: Session, plan: Plan, *, above_m: float = 0.2) -> None:
    """With an altitude hold, the vehicle stays clear of the ground through every held phase."""
    hold = plan.altitude_hold
    if hold is None:
        return
    z = s["altitude"]
    for p in s.phases():
        if p.kind in hold.kinds:
            inside = (z.time > p.start_s + 1.0) & (z.time < p.end_s)
            assert z.values()[inside].min() > above_m, (p.name, z.values()[inside].min())


def check_log_blocks(s: Session, result: FlightResult) -> None:
    """>= 99 % of the expected packets, 20 ms firmware spacing, file rows = delivered rows."""
    for name in BLOCKS:
        stream, stats = s[name], result.summary["blocks"][name]
        fw = np.asarray(stream.fw_time_s)
        expected = round((fw[-1] - fw[0]) / 0.02) + 1
        assert len(stream) >= 0.99 * expected, (name, len(stream), expected)
        assert stats["received"] == len(stream)  # every packet cflib delivered is in the file
        assert stats["expected"] == expected
        spacing = np.round(np.diff(fw) * 1000).astype(int)
        assert np.median(spacing) == 20 and (spacing % 20 == 0).all(), name
        assert stats["dropped"] == s.dropped()[name]


def check_log_blocks_jittery(s: Session, result: FlightResult) -> None:
    """For firmware whose log timer follows a busy host (SITL): about one packet per 20 ms of
    firmware time, median spacing 20 ms, file rows = delivered rows."""
    for name in BLOCKS:
        stream, stats = s[name], result.summary["blocks"][name]
        fw = np.asarray(stream.fw_time_s)
        assert len(stream) >= 0.8 * (fw[-1] - fw[0]) / 0.02, (name, len(stream))
        assert abs(np.median(np.diff(fw)) - 0.02) <= 0.002, name
        assert stats["received"] == len(stream)


def check_setpoints(s: Session, plan: Plan, *, complete: bool, slack_s: float = 0.0,
                    ) -> np.ndarray:
    """Scheduled setpoints as planned and on a 10 Hz grid; returns their rows. ``slack_s``
    widens the bounds on single late sends for a wall-clock backend on a busy host (SITL)."""
    sp = s["setpoints"].data
    sched = plan.compile()
    rows = sp[sp["tick"] >= 0]
    k = rows["tick"]
    assert (np.diff(k) == 1).all() and k[0] == 0
    if complete:
        assert len(rows) == len(sched)
    np.testing.assert_allclose(rows["roll"], sched.roll[k], atol=1e-4)
    np.testing.assert_allclose(rows["pitch"], sched.pitch[k], atol=1e-4)
    np.testing.assert_allclose(rows["yaw_rate"], sched.yaw_rate[k], atol=1e-4)
    np.testing.assert_array_equal(rows["phase_id"], sched.phase_id[k])
    # Thrust as planned, except where the altitude hold trims it (within its bound and limits).
    held = np.zeros(len(rows), dtype=bool)
    if sched.altitude_hold is not None:
        kinds = np.array([sched.phases[i].kind for i in rows["phase_id"]])
        held = np.isin(kinds, sched.altitude_hold.kinds)
        trim = rows["thrust"][held].astype(int) - sched.thrust[k][held]
        assert np.abs(trim).max() <= sched.altitude_hold.max_trim
        v = sched.vehicle
        assert v.thrust_min <= rows["thrust"][held].min() <= rows["thrust"][held].max() <= (
            v.thrust_max)
    np.testing.assert_array_equal(rows["thrust"][~held], sched.thrust[k][~held])
    # Drift-free deadlines t0 + k / f: lateness stays bounded whatever the flight's length
    # (drifting deadlines t_{k-1} + 1/f would accumulate every late send into the end).
    t = rows["host_time"]
    late = t - k / sched.rate_hz
    late -= late.min()
    assert np.median(late) < 0.02 and np.median(late[-20:]) < 0.02, np.median(late)
    # Never more than one setpoint period without a setpoint, from the thrust unlock on
    # (20 ms margin: the simulator steps in 10 ms; a real link's host jitter is a few ms).
    every = s["setpoints"].data["host_time"]
    assert np.diff(every).max() <= 1 / sched.rate_hz + 0.02 + slack_s, np.diff(every).max()
    assert late.max() < 0.05 + slack_s, late.max()
    span = (t[-1] - t[0]) / (len(t) - 1)
    assert abs(span - 1 / sched.rate_hz) < 2.0 / (len(t) - 1)
    return rows


def check_closed_with_stop(result: FlightResult) -> Session:
    """A readable, cleanly closed file whose last setpoint row is the stop (thrust 0)."""
    s = open_session(result.path)
    assert s.closed_cleanly and not s.problems
    last = s["setpoints"].data[-1]
    assert last["thrust"] == 0 and last["tick"] == -1
    assert any("stop setpoint sent" in e.text for e in s.events())
    return s


def check_fed_until_landed(s: Session, result: FlightResult, *, slack_s: float = 0.0) -> None:
    """After the stop, the stop setpoint went on every period (never near the firmware's 0.5 s
    level-out), each recorded, until the supervisor reported landed: ``supervisor.info``
    logged after the last one has neither the flying nor the locked bit, so the vehicle is left
    unlocked for its next flight."""
    fed = result.summary["setpoints"]["after_stop"]
    assert fed["ended"] == "landed", fed
    sp = s["setpoints"].data
    stops = np.flatnonzero((sp["tick"] == -1) & (sp["thrust"] == 0))
    after = sp[stops[stops > 0][0]:]  # from the stop (row 0 released the thrust lock)
    assert (after["thrust"] == 0).all() and (after["tick"] == -1).all()
    assert len(after) - 1 == fed["setpoints"] >= 15  # the 2 s is-flying hysteresis, at 10 Hz
    assert np.diff(after["host_time"]).max() <= 0.12 + slack_s
    battery = s["battery"]
    info = battery.data["info"].astype(int)  # supervisor.info
    assert battery.time[-1] > after["host_time"][0] and not info[-1] & 0x50, info  # landed
    assert info[battery.time < after["host_time"][0]][-1] & 0x10  # it was flying at the stop


def safety_events(s: Session) -> list:
    """The safety errors and warnings of a session, in order."""
    return [e for e in s.events() if e.source == "safety" and e.level in ("error", "warning")]


def check_descent(s: Session, *, thrust_ceiling: int, n: int, slack_s: float = 0.0) -> None:
    sp = s["setpoints"].data
    abort = sp[(sp["tick"] == -1) & (sp["thrust"] > 0)]
    assert len(abort) == n
    assert (abort["thrust"] <= thrust_ceiling).all()
    assert (abort["roll"] == 0).all() and (abort["pitch"] == 0).all()
    kinds = [k.decode() for k in s["phases"].data["kind"]]
    assert kinds[-1] == "abort"
    # One setpoint per 0.1 s deadline from the thrust unlock through the flight and the descent
    # to the stop: never more than one period without a setpoint (the simulation is paced by
    # the runner's clock, so this holds on a busy host too; 20 ms margin for the 10 ms steps).
    t = sp["host_time"]
    assert np.diff(t).max() <= 0.1 + 0.02 + slack_s, np.diff(t).max()  # slack: real time, SITL
    late = t[1:] - np.arange(len(t) - 1) * 0.1
    late -= late.min()
    assert late[-1] < 0.05 + slack_s
