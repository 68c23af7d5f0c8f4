"""A small valid plan used as the base for the error cases, and a line finder."""

from __future__ import annotations

import pytest

BASE = """\
name = "base"
setpoint_rate_hz = 10
hover_thrust = 39000

[vehicle]
max_roll_deg = 30.0
max_pitch_deg = 30.0
max_yaw_rate_deg_s = 200.0
thrust_min = 10000
thrust_max = 60000
min_vbat = 3.8

[safety]
on_abort = "descend"
descent_duration = 1.0
descent_thrust = 34000

[[phase]]
name = "up"
kind = "takeoff"
duration = 1.0
thrust_start = 20000
thrust_end = 42000

[[phase]]
name = "excite"
kind = "excitation"
duration = 3.1

[phase.roll]
signal = "prbs"
register_length = 5
amplitude = 20.0
seed = 3

[phase.yaw_rate]
signal = "doublet"
amplitude = 40.0
width = 0.5
start = 0.2

[[phase]]
name = "down"
kind = "landing"
duration = 1.0
thrust_start = 36000
thrust_end = 20000
"""


def line_of(text: str, needle: str, nth: int = 1) -> int:
    """1-based line number of the ``nth`` line containing ``needle``."""
    hits = [i + 1 for i, line in enumerate(text.splitlines()) if needle in line]
    return hits[nth - 1]


@pytest.fixture
def base_text() -> str:
    return BASE
