"""A second PRBS realisation: same sequence later, same inter-axis lags, text as flown."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main
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


@pytest.mark.parametrize("chips", [0, 1023, 500])
def test_only_the_seed_lines_change_and_no_advance_changes_nothing(chips, tmp_path):
    base = load_plan("prbs-3axis")
    text = advance_prbs(base, chips=chips).text
    (tmp_path / "advanced.toml").write_text(text, encoding="utf-8")
    check = CliRunner().invoke(main, ["plan", "check", str(tmp_path / "advanced.toml")])
    assert check.exit_code == 0 and "warning" not in check.output, check.output
    header, *lines = text.splitlines(keepends=True)
    assert header == f"# PRBS advanced by {chips} chips from the shipped plan (groundstation)\n"
    old = base.text.splitlines(keepends=True)
    differ = [(a, b) for a, b in zip(old, lines, strict=True) if a != b]
    if chips % 1023 == 0:  # a whole period: the same seeds, the same bytes
        assert differ == []
    else:  # three seeds; their comments stay at their column
        assert [a.split("=")[0] for a, _ in differ] == ["seed "] * 3
        assert all(a.index("#") == b.index("#") for a, b in differ if "#" in a)
