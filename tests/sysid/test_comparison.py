"""sysid.comparison: CompareResult acts as its fit array and says what was compared (how
sysid.compare fills it: test_validate.py)."""

from __future__ import annotations

import numpy as np
import pytest

from sysid.comparison import CompareResult


def _result(*, fit=(95.0, 40.0), horizon=None, window=None, model_stable=True,
            predictor_stable=True, diverged=False) -> CompareResult:
    fit = np.array(fit)
    return CompareResult(fit=fit, fits=fit[None, :], y_model=(np.zeros((3, 2)),),
                         y_measured=(np.zeros((3, 2)),), x0=(np.zeros((1, 4)),),
                         horizon=horizon, window=window, model_stable=model_stable,
                         predictor_stable=predictor_stable, diverged=diverged,
                         output_names=("gyro.x", "gyro.y"))


def test_it_behaves_as_the_fit_array():
    res = _result()
    np.testing.assert_array_equal(np.asarray(res), [95.0, 40.0])
    assert len(res) == 2 and res[0] == 95.0 and list(res) == [95.0, 40.0]
    np.testing.assert_array_equal(res >= 50, [True, False])
    np.testing.assert_array_equal(res - 40.0, [55.0, 0.0])
    np.testing.assert_array_equal(np.maximum(res, _result(fit=(10.0, 60.0))), [95.0, 60.0])
    assert float(np.mean(res)) == 67.5 and np.all(res > 0)
    copy = np.asarray(res)
    copy[0] = 0.0  # a copy: the result's fit is unchanged
    assert res.fit[0] == 95.0


@pytest.mark.parametrize(("kw", "mode"), [
    ({}, "simulation"),
    ({"window": 100}, "windowed simulation"),
    ({"horizon": 1}, "1-step prediction"),
    ({"horizon": 10}, "10-step prediction"),
])
def test_mode_names_what_was_compared(kw, mode):
    res = _result(**kw)
    assert res.mode == mode and res.summary().splitlines()[0] == f"{mode}:"


def test_summary_lists_each_channel_then_every_flag():
    assert _result().summary().splitlines() == ["simulation:", "  gyro.x:   95.00 %",
                                                "  gyro.y:   40.00 %"]
    flagged = _result(model_stable=False, predictor_stable=False, diverged=True).summary()
    assert flagged.splitlines()[3:] == [
        "  model is unstable (max |eig A| >= 1)",
        "  predictor A - KC is unstable: use sysid.stable_predictor(model)",
        "  model output diverged (non-finite)",
    ]

