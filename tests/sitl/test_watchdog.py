"""The setpoint watchdog of the real firmware, observed, against what ``sim://`` emulates.

Procedure (the same on both): fly with roll setpoints that each differ (5 deg + 0.01 deg per
setpoint, 50 Hz, 1.5 s, above hover thrust), then send nothing. The firmware's own log
(``controller.roll``: the desired roll; ``motor.m1..m4``; ``supervisor.info``) at 100 Hz, on its
own clock, shows when the last setpoint arrived, when the watchdog levelled the vehicle
(desired roll 0, motors still running) and when it stopped the motors and locked.
Known truth: ``supervisor.c`` (500 ms level-out, 2000 ms shutdown, then locked).
"""

from __future__ import annotations

import time

import numpy as np

import groundstation.sim as gsim
from groundstation.flight.clock import clock_for_uri
from groundstation.sim.vehicle import SimVehicle

from ..sim_crtp.helpers import Recorder, connect
from . import backend

BLOCK = {"wd": ["controller.roll", "motor.m1", "motor.m2", "motor.m3", "motor.m4",
                "supervisor.info"]}
LOCKED = 0x40


def between(fw_s: np.ndarray, first: int, then: int) -> tuple[float, float]:
    """The time from the event first shown by log sample ``first`` to the one first shown by
    ``then``, as (least, most): each happened between the sample that first shows it and the
    one before. A log sample the host did not get, or a log task held up on a busy host,
    widens the bracket instead of moving a point estimate (0.377 s for the 0.5 s level-out
    was seen from the first samples alone, the real firmware beside three busy processes)."""
    return fw_s[then - 1] - fw_s[first], fw_s[then] - fw_s[first - 1]


def observe_watchdog(uri: str, *, thrust: int) -> dict[str, float]:
    clock = clock_for_uri(uri)
    with connect(uri, toc_cache=True) as scf:
        cf = scf.cf
        rec = Recorder(cf, blocks=BLOCK, period_ms=10)
        t = clock.now()
        cf.commander.send_setpoint(0, 0, 0, 0)  # release the thrust lock
        n = 75
        for k in range(n):
            t += 0.02
            clock.sleep_until(t)
            cf.commander.send_setpoint(5.0 + 0.01 * k, 0, 0, thrust)
        # Silence: the watchdog's turn. Wait (generously, on a busy host) until the log shows
        # the vehicle locked, then stop reading.
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:
            clock.sleep_until(clock.now() + 0.2)
            fw_ms, v = rec.rows("wd")
            if len(v) and int(v[-1, 5]) & LOCKED and (v[-1, 1:5] == 0).all():
                break
    last = 5.0 + 0.01 * (n - 1)
    fw_s = (fw_ms - fw_ms[0]) / 1000.0
    i_last = np.flatnonzero(np.abs(v[:, 0] - last) < 0.004)[0]
    after = np.arange(len(fw_s)) > i_last
    i_level = np.flatnonzero(after & (v[:, 0] == 0.0))[0]
    i_off = np.flatnonzero(after & (v[:, 1:5] == 0).all(axis=1))[0]
    return {"level_s": between(fw_s, i_last, i_level), "stop_s": between(fw_s, i_last, i_off),
            "running_when_level": float(v[i_level, 1:5].min()),
            "locked": bool(int(v[-1, 5]) & LOCKED), "locked_before": bool(int(v[0, 5]) & LOCKED)}


def on_both(observe, *, address: int) -> tuple[dict, dict]:
    """``observe(uri, thrust=...)`` on ``sim://`` (20x), then on a fresh real firmware, each
    3000 PWM above its hover thrust: (simulated, real)."""
    gsim.install()
    uri = f"sim://{address + int(time.monotonic() * 1000) % 1000}?speed=20"
    try:
        sim = observe(uri, thrust=SimVehicle().hover_thrust() + 3000)
    finally:
        gsim.close_all()
    try:
        v = backend.start_vehicle()
        real = observe(v.uri, thrust=v.peer.hover_pwm() + 3000)
    finally:
        backend.close_all()
    return sim, real


def test_real_firmware_watchdog_matches_the_simulated_one():
    sim, real = on_both(observe_watchdog, address=9000)
    # sim://: exact to the log period. SITL: its log, supervisor and stabilizer run as threads of
    # a real-time process on a busy host (measured here: 0.531 s and 2.001 s).
    for name, obs, tol in (("sim", sim, 0.001), ("sitl", real, 0.1)):
        for key, truth in (("level_s", 0.5), ("stop_s", 2.0)):
            least, most = obs[key]
            assert least - tol <= truth <= most + tol, (name, key, obs)
        assert obs["running_when_level"] > 0, (name, obs)  # levelled, still flying
        assert obs["locked"] and not obs["locked_before"], (name, obs)


STOP_BLOCK = {"st": ["motor.m1", "motor.m2", "motor.m3", "motor.m4", "supervisor.info"]}


def observe_after_the_stop(uri: str, *, thrust: int) -> dict[str, float]:
    """Fly 0.5 s, send one stop setpoint and keep sending it every 0.1 s until the log says
    landed (bit 4 clear; 5 s at most); then fly 0.5 s again, one stop, and silence until the
    log says locked (5 s at most). Times from the motors' stop (firmware clock, s)."""
    clock = clock_for_uri(uri)
    out: dict[str, float] = {}
    with connect(uri, toc_cache=True) as scf:
        cf = scf.cf
        rec = Recorder(cf, blocks=STOP_BLOCK, period_ms=10)
        cf.commander.send_setpoint(0, 0, 0, 0)  # release the thrust lock
        for fed in (True, False):
            t = clock.now()
            for _ in range(25):
                t += 0.02
                clock.sleep_until(t)
                cf.commander.send_setpoint(0, 0, 0, thrust)
            cf.commander.send_stop_setpoint()
            n_before = len(rec.rows("st")[0])
            deadline = time.monotonic() + 20.0  # wall clock: a busy host
            while time.monotonic() < deadline and clock.now() < t + 5.0:
                clock.sleep_until(clock.now() + 0.1)
                if fed:
                    cf.commander.send_stop_setpoint()
                fw_ms, v = rec.rows("st")
                info = v[n_before:, 4].astype(int)
                if len(info) and ((info[-1] & LOCKED) if not fed else not info[-1] & 0x10):
                    break
            fw_ms, v = rec.rows("st")
            fw_s, info = fw_ms / 1000.0, v[:, 4].astype(int)
            off = n_before + np.flatnonzero((v[n_before:, :4] == 0).all(axis=1))[0]
            end = n_before + np.flatnonzero(((info & LOCKED) if not fed else ~info & 0x10)
                                            [n_before:])
            key = "fed" if fed else "silent"
            out[f"{key}_s"] = between(fw_s, off, end[0]) if len(end) else (np.inf, np.inf)
            out[f"{key}_locked"] = bool(info[-1] & LOCKED)
    return out


def test_after_a_stop_the_real_firmware_locks_unless_fed_as_the_simulated_one():
    """What the ground station's stop feed rests on (``groundstation.flight.commander``): after
    a stop setpoint the supervisor counts the vehicle flying 2 s more; fed stop setpoints it
    reports landed then, left silent it locks then (level-out has no way to Landed)."""
    sim, real = on_both(observe_after_the_stop, address=8000)
    for name, obs, tol in (("sim", sim, 0.01), ("sitl", real, 0.15)):
        for key in ("fed_s", "silent_s"):
            least, most = obs[key]
            assert least - tol <= 2.0 <= most + tol, (name, key, obs)
        assert not obs["fed_locked"] and obs["silent_locked"], (name, obs)
