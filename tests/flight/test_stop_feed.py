"""What the stop's feed reads in ``supervisor.info`` (``Commander._supervisor_says``), bit by
bit as ``supervisor.c`` sets them; the whole feed is flown in tests/flight/test_fly_plans.py,
test_safety.py and test_link_watch.py."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from groundstation.flight.commander import Commander


def _says(info: int | None, *, after_stop: bool = True) -> str | None:
    telemetry = SimpleNamespace(supervisor=info, supervisor_t=5.0 if after_stop else 3.0,
                                stop_t=4.0)
    commander = Commander.__new__(Commander)
    commander.telemetry = telemetry
    return commander._supervisor_says()


@pytest.mark.parametrize(("info", "said"), [
    (0x1E, ""),          # flying (Flying or WarningLevelOut): feed on
    (0x0E, "landed"),    # armed, auto-arm, can fly: Landed (SITL logs 14)
    (0x44, "locked"),    # locked, disarmed (SITL logs 68): never "landed"
    (0x84, "crashed"),   # tumbled in flight: stopped, not flying, not locked: never "landed"
    (0x01, "landed"),    # a disarmed Brushless at rest
])
def test_the_feed_reads_each_state_of_the_supervisor(info, said):
    assert _says(info) == said


def test_a_value_from_before_the_stop_is_not_read_and_no_value_is_none():
    assert _says(0x0E, after_stop=False) == ""  # sampled before the stop: wait for a fresh one
    assert _says(None) is None                  # no supervisor.info in the log: feed blind
