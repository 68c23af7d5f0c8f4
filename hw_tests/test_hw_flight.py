"""The simulator flight tests (tests/flight) against whatever ``--uri`` names: a real Crazyflie
on a Crazyradio, or ``sim://0?speed=20`` to try the tests themselves.

Safety first: fly over a soft surface in a clear space; ``hover-check`` rises about a metre.
The motors' stop is observed in the recorded log (motor commands at 0 after the stop setpoint),
which is what the vehicle itself reports.
"""

from __future__ import annotations

import os
import signal

import numpy as np

from groundstation.flight import fly_plan
from groundstation.plan import load_plan
from tests.flight.checks import (
    check_closed_with_stop,
    check_fed_until_landed,
    check_log_blocks,
    check_setpoints,
)


def _motors_stopped_after_stop(s) -> None:
    sp = s["setpoints"].data
    t_stop = sp["host_time"][(sp["tick"] == -1) & (sp["thrust"] == 0)][1]  # row 0: the unlock
    motors = s["motors"]
    after = motors.values()[motors.time > t_stop + 0.1]
    assert len(after) > 0 and (after == 0).all()


def test_hover_check_flies_and_records(cf_uri, cf_arm, tmp_path):
    plan = load_plan("hover-check")
    result = fly_plan(plan=plan, out=tmp_path, uri=cf_uri, arm=cf_arm)
    assert not result.aborted, result.cause
    s = check_closed_with_stop(result)
    check_log_blocks(s, result)
    check_setpoints(s, plan, complete=True)
    _motors_stopped_after_stop(s)
    check_fed_until_landed(s, result, slack_s=0.05)  # left unlocked for the next flight
    assert [n.decode() for n in s["phases"].data["name"]] == [p.name for p in plan.phases]


def test_ctrl_c_in_hover_descends_and_stops(cf_uri, cf_arm, tmp_path):
    plan = load_plan("hover-check")
    hover = next(p for p in plan.compile().phases if p.kind == "hover")

    def hook(k: int) -> None:
        if k == hover.start_tick + 10:
            os.kill(os.getpid(), signal.SIGINT)

    result = fly_plan(plan=plan, out=tmp_path, uri=cf_uri, tick_hook=hook, arm=cf_arm)
    assert "SIGINT" in result.cause
    s = check_closed_with_stop(result)
    assert [k.decode() for k in s["phases"].data["kind"]][-1] == "abort"
    _motors_stopped_after_stop(s)
    check_fed_until_landed(s, result, slack_s=0.05)
    assert np.isfinite(s["battery"].values()).all()
