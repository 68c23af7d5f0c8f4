"""A second PRBS realisation: same sequence later, same inter-axis lags, text as flown."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.errors import PlanError
from groundstation.plan import load_plan, parse_plan
from groundstation.plan.variants import advance_prbs


def test_advanced_plan_is_the_same_sequence_shifted_with_the_same_axis_lags():
    base = load_plan("prbs-3axis")
    chips = 500
    other = advance_prbs(base, chips=chips)
    s0, s1 = base.compile(), other.compile()
    exc = next(p for p in s0.phases if p.kind == "excitation")
    clock = next(e for e in base.phases[exc.id].excitation if e.axis == "roll").clock_period
    k = slice(exc.start_tick, exc.end_tick)
    for axis in ("roll", "pitch", "yaw_rate"):
        a, b = getattr(s0, axis)[k], getattr(s1, axis)[k]
        assert not np.array_equal(a, b)
        # one full period of the m-sequence: b is a advanced by `chips` chips, cyclically
        np.testing.assert_array_equal(b, np.roll(a, -chips * clock))
    # the flown text is what was parsed: re-parsing it gives the same schedule
    again = parse_plan(text=other.text, source="x", name=other.name).compile()
    np.testing.assert_array_equal(again.roll, s1.roll)
    assert other.text.startswith("# PRBS advanced by 500 chips")


def test_plans_without_prbs_are_refused():
    with pytest.raises(PlanError, match="no PRBS"):
        advance_prbs(load_plan("hover-check"), chips=10)
