"""The Rerun live view as a listener of a real (simulated) flight: what the file has, it has."""

from __future__ import annotations

import numpy as np

from cfsession import open_session
from groundstation.flight import fly_plan
from groundstation.live import open_view
from tests.viz.rrd import blueprint_views, load


def test_live_view_receives_every_row_of_the_flight(sim_uri, tmp_path):
    rrd = tmp_path / "live.rrd"
    view = open_view(mode="save", name="hover-check", rrd_path=rrd)
    result = fly_plan(plan="hover-check", out=tmp_path, uri=sim_uri(), listeners=[view])
    assert not result.aborted, result.cause
    assert view.dropped_rows == 0
    s = open_session(result.path)
    entities = load(rrd)
    for axis in "xyz":
        got = entities[f"/gyro/{axis}"]
        np.testing.assert_allclose(got.scalars(), s["gyro"].data[axis], rtol=1e-6)
        np.testing.assert_allclose(got.times["host_time"], s["gyro"].time, atol=1e-6)
    for i in range(1, 5):
        assert len(entities[f"/motors/m{i}"].scalars()) == len(s["motors"])
    assert len(entities["/acc/z"].scalars()) == len(s["acc"])
    # the attitude block reaches the view, in the panel of the roll/pitch setpoints
    assert len(entities["/attitude/pitch"].scalars()) == len(s["attitude"])
    panels = blueprint_views(rrd)
    assert any({"/setpoints/pitch", "/attitude/pitch"} <= set(v) for v in panels.values())
    phase_entities = [e for e in entities if "phase" in e]
    assert phase_entities, sorted(entities)
