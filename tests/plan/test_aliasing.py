"""Aliased motor logs and the design's answer (``groundstation.plan.aliasing``).

Known truth: a 1 kHz motor signal built as the firmware makes it (a 500 Hz attitude D term on a
yaw estimate that steps at 100 Hz: a one-tick pulse every 10 ms, proportional to the yaw rate),
logged at 50 Hz at a drifting phase, against the same signal averaged over each log period.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.plan import load_plan, parse_plan
from groundstation.plan.aliasing import ALIAS_SHARE, MOTOR_INPUTS, axis_shares, top_band_share
from groundstation.plan.design import ModelFacts, design_plan
from tests.sysid.flights import known_system, write_flight

GYROS = ("gyro.x", "gyro.y", "gyro.z")
YAW = np.array([1.0, -1.0, 1.0, -1.0])
ROLL = np.array([-1.0, -1.0, 1.0, 1.0])


def _firmware_motors(seconds: float = 60.0, *, d_term: bool, seed: int = 0) -> np.ndarray:
    """(N, 4) motor commands at 1 kHz: hover, a smooth roll and yaw command (a 0.3 s PRBS
    through a 30 ms lag), and with ``d_term`` the yaw attitude D term's pulses: 0.35 x the
    yaw step of the 100 Hz estimate x 500 Hz, x 120 (rate P gain), held for 2 ms."""
    rng = np.random.default_rng(seed)
    n = int(seconds * 1000)
    chips = np.repeat(rng.choice([-1.0, 1.0], size=(n // 300 + 1, 2)), 300, axis=0)[:n]
    smooth = np.zeros_like(chips)
    for k in range(1, n):  # first-order lag, 30 ms
        smooth[k] = smooth[k - 1] + (chips[k] - smooth[k - 1]) / 30.0
    rate = 50.0 * smooth[:, 1]  # deg/s
    yaw_est = np.repeat(np.cumsum(rate[::10]) / 100.0, 10)[:n]  # 100 Hz estimator steps
    cmd_yaw = 2000.0 * smooth[:, 1]
    if d_term:
        step = np.diff(yaw_est[::2], prepend=yaw_est[0])  # per 500 Hz controller tick
        cmd_yaw += np.repeat(-0.35 * step * 500.0 * 120.0, 2)[:n]
    cmd_roll = 8000.0 * smooth[:, 0]
    return 40000.0 + np.outer(cmd_roll, ROLL) / 2 + np.outer(cmd_yaw, YAW)


def _logged(m1k: np.ndarray, *, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """50 Hz samples, each up to 10 ms late (a log timer's jitter against the controller, as
    on the firmware in the loop), and the means over the 20 ms before each sample."""
    rng = np.random.default_rng(seed)
    idx = np.arange(20, len(m1k) - 20, 20) + rng.integers(0, 10, size=(len(m1k) - 40) // 20 + 1
                                                          )[: len(range(20, len(m1k) - 20, 20))]
    means = np.cumsum(np.vstack([np.zeros(4), m1k]), axis=0)
    return m1k[idx], (means[idx + 1] - means[idx - 19]) / 20.0


def test_sampled_d_term_pulses_are_aliased_and_means_or_no_d_term_are_not():
    sampled, mean = _logged(_firmware_motors(d_term=True))
    clean, _ = _logged(_firmware_motors(d_term=False))
    names = MOTOR_INPUTS
    got = axis_shares([sampled], input_names=names)
    assert got["yaw_rate"] > 2 * ALIAS_SHARE  # the pulses, sampled at random
    assert axis_shares([mean], input_names=names)["yaw_rate"] < got["yaw_rate"] / 3
    assert axis_shares([clean], input_names=names)["yaw_rate"] < ALIAS_SHARE / 5
    assert got["roll"] < ALIAS_SHARE  # no D term on roll: smooth
    # inputs that are not the four motors: nothing to say
    assert axis_shares([sampled], input_names=("a", "b", "c", "d")) == {}
    assert np.isnan(top_band_share(np.ones(1000))) and np.isnan(top_band_share(np.ones(10)))


def _facts() -> ModelFacts:
    return ModelFacts(source="m.json", poles=np.exp(-0.02 / np.array([0.2, 2.0])), dt=0.02,
                      output_names=GYROS, fits=dict.fromkeys(GYROS, 80.0), fit_source="given")


@pytest.mark.parametrize(("plan", "aliasing", "firmware", "expect"), [
    ("prbs-3axis", {"yaw_rate": 0.3, "roll": 0.02}, {"pid_attitude.yaw_kd": 0.35}, 0.35),
    ("prbs-3axis", {"yaw_rate": 0.3}, {"pid_attitude.yaw_kd": 0.0}, None),  # no D term
    ("prbs-3axis", {"yaw_rate": 0.03}, {"pid_attitude.yaw_kd": 0.35}, None),  # not aliased
    ("prbs-3axis", {"yaw_rate": 0.3}, {}, None),  # firmware not known
    ("roll-only", {"yaw_rate": 0.3}, {"pid_attitude.yaw_kd": 0.35}, None),  # yaw not excited
])
def test_design_turns_the_d_term_off_only_where_it_aliased(plan, aliasing, firmware, expect):
    design = design_plan(load_plan(plan), _facts(), name="next", flown=set(),
                         aliasing=aliasing, firmware=firmware)
    params = dict(design.plan.parameters)
    changed = [c for c in design.changes if c.path[0] == "parameters"]
    if expect is None:
        assert not params and not changed
        return
    assert params == {"pid_attitude.yaw_kd": 0.0}
    assert changed[0].old == expect and "30.0 %" in changed[0].why
    # designed again from the designed plan: the D term is already off, nothing to change
    again = design_plan(design.plan, _facts(), name="next2", flown=set(), aliasing=aliasing,
                        firmware=firmware)
    assert dict(again.plan.parameters) == params
    assert not [c for c in again.changes if c.path[0] == "parameters"]


def test_plan_design_reads_the_flown_motors_and_firmware(tmp_path):
    """The command: a flown session whose logged motors carry random pulses on the yaw
    combination, recorded with the firmware's parameters, gives a plan that flies without
    the yaw D term; `plan check` and `plan show` say so."""
    system = known_system()
    model = tmp_path / "model.json"
    system.replace(input_names=list(MOTOR_INPUTS),
                   output_names=["acc.x", "acc.y", "acc.z", *GYROS]).save(model)
    rng = np.random.default_rng(1)
    n = 2500
    pulses = np.outer(rng.choice([0.0, 3000.0, -3000.0], size=n, p=[0.6, 0.2, 0.2]), YAW)
    params = {"pid_attitude": {"yaw_kd": 0.35, "roll_kd": 0.0}, "stabilizer": {"estimator": 2}}
    flown = [write_flight(tmp_path / f"f{i}.h5", system=system, seed=i, n=n,
                          metadata={"params": params, "plan_text": load_plan("prbs-3axis").text,
                                    "plan_name": "prbs-3axis"},
                          pwm_extra=pulses if i == 0 else None)
             for i in range(2)]
    out = tmp_path / "next.toml"
    res = CliRunner().invoke(main, ["plan", "design", "--model", str(model), "--out", str(out),
                                    "--flown", str(flown[0].path), "--flown", str(flown[1].path)])
    assert res.exit_code == 0, res.output
    assert "pid_attitude.yaw_kd = 0.0" in res.output and "was 0.35" in res.output
    plan = parse_plan(text=out.read_text(encoding="utf-8"), source=str(out), name="next")
    assert dict(plan.parameters) == {"pid_attitude.yaw_kd": 0.0}
    check = CliRunner().invoke(main, ["plan", "check", str(out)])
    assert check.exit_code == 0 and "pid_attitude.yaw_kd = 0" in check.output
    show = CliRunner().invoke(main, ["plan", "show", str(out)])
    assert "parameters.pid_attitude.yaw_kd: the motors' yaw_rate combination" in show.output


@pytest.mark.parametrize("params", ["[1, 2", "[1, 2]", {"pid_attitude": "x"},
                                    {"pid_attitude": {"yaw_kd": "0.35"}}])
def test_hostile_recorded_parameters_mean_no_firmware_knowledge(tmp_path, params):
    """A flown session whose parameters attribute is damaged: the design goes on without the
    firmware's values (so no D term is changed) instead of failing."""
    system = known_system()
    model = tmp_path / "model.json"
    system.replace(input_names=list(MOTOR_INPUTS),
                   output_names=["acc.x", "acc.y", "acc.z", *GYROS]).save(model)
    rng = np.random.default_rng(1)
    pulses = np.outer(rng.choice([0.0, 3000.0, -3000.0], size=2500, p=[0.6, 0.2, 0.2]), YAW)
    flown = write_flight(tmp_path / "f.h5", system=system, seed=0, pwm_extra=pulses,
                         metadata={"params": params, "plan_text": load_plan("prbs-3axis").text,
                                   "plan_name": "prbs-3axis"})
    out = tmp_path / "next.toml"
    res = CliRunner().invoke(main, ["plan", "design", "--model", str(model), "--out", str(out),
                                    "--flown", str(flown.path)])
    assert res.exit_code == 0, res.output
    assert "yaw_rate" in res.output and "[parameters" not in out.read_text(encoding="utf-8")
