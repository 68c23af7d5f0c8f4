"""cfcommon.rerun.entity_path and panel_title: the names both sides give entities and panels."""

from __future__ import annotations

import pytest
import rerun as rr
from rerun.chunk import RrdReader

from cfcommon.rerun import TITLE_MAX, entity_path, panel_title

NAMES = ["stateEstimate+controller", "rate gyro", "a/b", "c\\d", "$origin", "#1", "é [°]",
         "x.y", "-m"]


def test_the_logged_path_the_stored_path_and_a_query_agree(tmp_path) -> None:
    rec = rr.RecordingStream("names")
    rec.save(tmp_path / "n.rrd")
    for i, name in enumerate(NAMES):
        rec.log(entity_path(name, "v", base="/top"), rr.Scalars(float(i)))
    rec.disconnect()
    stored = {c.entity_path for c in RrdReader(tmp_path / "n.rrd").stream().to_chunks()}
    for name in NAMES:
        path = entity_path(name, "v", base="/top")
        assert path in stored, (name, sorted(stored))  # one part each, as Rerun prints it
        for query in (path, path.rsplit("/", 1)[0] + "/**"):  # what a layout names
            got = {c.entity_path for c in RrdReader(tmp_path / "n.rrd").stream().filter(
                content=[query]).to_chunks()}
            assert got == {path}, (query, got)


def test_entity_path_shapes() -> None:
    assert entity_path() == "/" and entity_path(base="sysid/") == "/sysid"
    assert entity_path("exp0", "gyro.x", base="/sysid") == "/sysid/exp0/gyro.x"
    assert entity_path("stateEstimate+controller", "r_roll") == \
        "/stateEstimate\\+controller/r_roll"
    with pytest.raises(ValueError, match="must not be empty"):
        entity_path("a", "")


@pytest.mark.parametrize(("label", "unit", "title"), [
    ("gyro", "deg/s", "gyro [deg/s]"),  # short: as it is
    ("controller.r_roll x motor.m1", "", "r_roll x m1"),  # the groups go first
    ("controller.actuatorThrust", "", "actuatorThrust"),
    ("stateEstimate+controller", "deg/s", "stateEstima… [deg/s]"),  # then the label is cut
    ("x", "a very long unit name", "x [a very long unit…"),
])
def test_panel_title(label, unit, title) -> None:
    assert panel_title(label, unit=unit) == title
    assert len(title) <= TITLE_MAX
