"""Every panel of every blueprint the project writes shows data.

The .rrd files are written by the real commands (replay, plan show, sysid identify, compare and
sweep) and a live view fed like a flight; each blueprint is read back from the file and every
view's content query is resolved against the file's entities with Rerun's matching rules
(:func:`tests.viz.rrd.resolve`): no viewer is needed. A view that resolves to nothing would say
"No data available" in the viewer.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from groundstation.cli import main as gs_main
from groundstation.live import open_view
from sysid.cli import main as sysid_main
from tests.sysid.flights import known_system, write_flight
from tests.viz.rrd import View, explicit_entities, load, resolve, views
from tests.viz.sessions import flight_rows, flight_specs, write_session

FAST = ["--order", "4", "--past", "20", "--future", "10"]


def _run(main, *args) -> None:
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bp")
    out = {}
    session = write_session(d / "flight.h5")
    _run(gs_main, "replay", session, "--rrd", d / "replay.rrd")
    out["replay"] = d / "replay.rrd"
    _run(gs_main, "plan", "show", "prbs-3axis", "--rrd", d / "plan.rrd")
    out["plan show"] = d / "plan.rrd"
    view = open_view(mode="save", name="live", rrd_path=d / "live.rrd")
    view.begin(streams=flight_specs(), metadata={"plan_name": "live"})
    for stream, rows in flight_rows().items():
        view.rows(stream, rows)
    view.end(summary={"ok": True})
    out["flight view"] = d / "live.rrd"
    flight = write_flight(d / "sysid.h5", system=known_system(), seed=3, n=1200)
    _run(sysid_main, "identify", flight.path, *FAST, "--rrd", d / "identify.rrd",
         "--out", d / "model.h5")
    out["identify"] = d / "identify.rrd"
    _run(sysid_main, "compare", d / "model.h5", flight.path, "--horizon", "3",
         "--rrd", d / "compare.rrd")
    out["compare"] = d / "compare.rrd"
    _run(sysid_main, "sweep", flight.path, "--pasts", "15,20", "--futures", "10",
         "--orders", "3,4", "--rrd", d / "sweep.rrd")
    out["sweep"] = d / "sweep.rrd"
    return out


KINDS = ["replay", "plan show", "flight view", "identify", "compare", "sweep"]


@pytest.mark.parametrize("kind", KINDS)
def test_every_panel_shows_data(recordings, kind) -> None:
    path = recordings[kind]
    entities = load(path, sort_by=None)
    found = views(path)
    assert len(found) >= 4, [v.name for v in found]
    for view in found:
        shown = resolve(view, entities)
        assert shown, f"{kind}: panel {view.name!r} ({view.kind}, {view.query}) shows nothing"
        for named in explicit_entities(view):  # a listed entity must exist and hold data
            assert named in shown, f"{kind}: panel {view.name!r} names {named}, which is empty"


def _by_name(path: Path) -> dict[str, View]:
    return {v.name: v for v in views(path)}


def test_identification_report_panels(recordings) -> None:
    ents = load(recordings["identify"], sort_by=None)
    by_name = _by_name(recordings["identify"])
    # measured and model of every output channel, not an empty plot
    gyro_x = [resolve(v, ents) for v in views(recordings["identify"])
              if v.name == "gyro.x" and v.origin == "/sysid/windowed_simulation"]
    assert gyro_x[0] == ["/sysid/windowed_simulation/exp0/gyro.x/measured",
                      "/sysid/windowed_simulation/exp0/gyro.x/model"]
    # the chosen order is drawn over the singular values; the log chart starts at 0
    bars = resolve(by_name["singular values (order in red)"], ents)
    assert bars == ["/sysid/order/singular_values", "/sysid/order/singular_values/chosen"]
    chosen = ents["/sysid/order/singular_values/chosen"].static["BarChart:values"][0]["buffer"]
    assert len(chosen) == 4
    log10 = ents["/sysid/order/singular_values/log10"].static["BarChart:values"][0]["buffer"]
    assert min(log10) == 0.0 and all(v >= 0 for v in log10)
    # a zoomed pole view near z = 1; no sweep panel without a sweep
    zoom = by_name["poles near z = 1"].properties["VisualBounds2D:range"][0]
    assert zoom["x_range"][1] - zoom["x_range"][0] < 0.5
    assert "sweep pole clouds" not in by_name
    assert "sweep pole clouds" in _by_name(recordings["sweep"])
    # short point labels (the table holds the numbers), and a table per pole set
    labels = ents["/sysid/poles/A"].static["Points2D:labels"]
    assert labels == ["A1", "A2", "A3", "A4"]
    table = ents["/sysid/poles/table"].static["TextDocument:text"][0]
    assert "| A1 |" in table and "| K4 |" in table


def test_flight_view_panels_are_small_panel_friendly(recordings) -> None:
    for view in views(recordings["replay"]):
        if view.kind == "TimeSeries":
            assert view.properties.get("PlotLegend:visible") == [False], view.name
            assert len(view.name) <= 20, view.name  # titles fit a small panel
