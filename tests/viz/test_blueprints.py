"""Every panel of every blueprint the project writes shows data.

The .rrd files are written by the real commands (replay of a flight and of imported cfclient
and uSD logs, plan show, sysid identify (also with --validate), compare, sweep and resid) and
a live view fed like a flight; each blueprint is read back from the file and every view's
content query is resolved against the file's entities by Rerun's own entity-path filter
(:func:`tests.viz.rrd.resolve`): no viewer is needed. A view that resolves to nothing would
say "No data available" in the viewer; a time series without the time panel's timeline would
be empty.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import rerun as rr
import rerun.blueprint as rrb
from click.testing import CliRunner

import sysid
from cfcommon.rerun import TITLE_MAX
from cfsession.schema import log_block_spec
from groundstation.cli import main as gs_main
from groundstation.live import open_view
from sysid import viz
from sysid.cli import main as sysid_main
from sysid.session_io import load_session
from tests.paths import CRAZYPAD
from tests.sysid.flights import known_system, write_flight
from tests.viz.rrd import View, explicit_rules, load, resolve, timeline, views
from tests.viz.sessions import flight_rows, flight_specs, write_session

FAST = ["--order", "4", "--past", "20", "--future", "10"]
ODD = "rate gyro/raw\\1"  # a space, a slash and a backslash: each breaks an unescaped path


def _run(main, *args) -> None:
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, res.output


def _cfclient_log(folder: Path) -> Path:
    """A cfclient CSV block of two groups, named as cfclient names it after the block."""
    folder.mkdir()
    k = np.arange(60)
    header = ["Timestamp", "stateEstimate.x", "stateEstimate.z", "controller.roll",
              "controller.pitch", "controller.rollRate", "controller.cmd_thrust"]
    rows = [[1000 + 10 * i, 0.01 * i, 0.3, np.sin(0.1 * i), -0.5, 2.0 * np.cos(0.1 * i),
             30000 + i] for i in k]
    (folder / "stateEstimate+controller-20240101T10-00-00.csv").write_text(
        "\n".join([",".join(header), *(",".join(f"{v:g}" for v in r) for r in rows)]) + "\n")
    return folder


def _live(path: Path, *, specs, rows) -> Path:
    view = open_view(mode="save", name="live", rrd_path=path)
    view.begin(streams=specs, metadata={"plan_name": "live"})
    for stream, rs in rows.items():
        view.rows(stream, rs)
    view.end(summary={"ok": True})
    return path


@pytest.fixture(scope="module")
def recordings(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("bp")
    out = {}
    _run(gs_main, "replay", write_session(d / "flight.h5"), "--rrd", d / "replay.rrd")
    out["replay"] = d / "replay.rrd"
    _run(gs_main, "replay", write_session(d / "liveid.h5", live_id=40), "--rrd", d / "lid.rrd")
    out["replay with live id"] = d / "lid.rrd"
    _run(gs_main, "replay", write_session(d / "renamed.h5", rename={
        "setpoints": "commander", "link": "radio"}), "--rrd", d / "renamed.rrd")
    out["replay of streams named otherwise"] = d / "renamed.rrd"
    _run(gs_main, "import", _cfclient_log(d / "cfclient"), "--out", d / "imported")
    _run(gs_main, "replay", d / "imported" / "cfclient.h5", "--rrd", d / "csv.rrd")
    out["replay cfclient import"] = d / "csv.rrd"
    if (CRAZYPAD / "controller_E8_log00").is_file():
        _run(gs_main, "import", CRAZYPAD / "controller_E8_log00", "--out", d / "imported")
        _run(gs_main, "replay", d / "imported" / "controller_E8_log00.h5", "--rrd",
             d / "usd.rrd")
        out["replay uSD import"] = d / "usd.rrd"
    _run(gs_main, "plan", "show", "prbs-3axis", "--rrd", d / "plan.rrd")
    out["plan show"] = d / "plan.rrd"
    out["flight view"] = _live(d / "live.rrd", specs=flight_specs(), rows=flight_rows())
    odd = log_block_spec(name=ODD, variables=[("gyro.x", "float"), ("pm.vbat", "float")],
                         period_s=0.01)
    out["odd names"] = _live(d / "odd.rrd", specs=[*flight_specs(), odd], rows={
        **flight_rows(), ODD: [(0.01 * i, i, float(i), 4.0) for i in range(50)]})
    flight = write_flight(d / "sysid.h5", system=known_system(), seed=3, n=1200)
    _run(sysid_main, "identify", flight.path, *FAST, "--rrd", d / "identify.rrd",
         "--out", d / "model.h5")
    out["identify"] = d / "identify.rrd"
    other = write_flight(d / "other.h5", system=known_system(), seed=4, n=1200)
    _run(sysid_main, "identify", flight.path, *FAST, "--validate", other.path,
         "--rrd", d / "validate.rrd")
    out["identify with validation"] = d / "validate.rrd"
    _run(sysid_main, "compare", d / "model.h5", flight.path, "--horizon", "3",
         "--rrd", d / "compare.rrd")
    out["compare"] = d / "compare.rrd"
    _run(sysid_main, "sweep", flight.path, "--pasts", "15,20", "--futures", "10",
         "--orders", "3,4", "--rrd", d / "sweep.rrd")
    out["sweep"] = d / "sweep.rrd"
    _run(sysid_main, "resid", d / "model.h5", flight.path, "--max-lag", "10",
         "--rrd", d / "resid.rrd")
    out["resid"] = d / "resid.rrd"
    model = sysid.load_model(d / "model.h5")  # the report with residuals in one layout
    data = load_session(flight.path, inputs=model.input_names, outputs=model.output_names,
                        dt=model.dt)
    rec, _ = viz.open_recording(name="all", mode="save", rrd_path=d / "all.rrd")
    viz.log_identification(rec=rec, model=model, residuals=sysid.residuals(model, data))
    viz.close_file(rec, d / "all.rrd")
    out["identify with residuals"] = d / "all.rrd"
    return out


KINDS = ["replay", "replay with live id", "replay of streams named otherwise",
         "replay cfclient import", "replay uSD import", "plan show", "flight view",
         "odd names", "identify", "identify with validation", "compare", "sweep", "resid",
         "identify with residuals"]
FLIGHT_VIEWS = ["replay", "replay with live id", "replay of streams named otherwise",
                "replay cfclient import", "replay uSD import", "flight view", "odd names"]


def _recording(recordings: dict[str, Path], kind: str) -> Path:
    if kind not in recordings:
        pytest.skip(f"shared CrazyPAD logs not found at {CRAZYPAD}")
    return recordings[kind]


@pytest.mark.parametrize("kind", KINDS)
def test_every_panel_shows_data(recordings, kind) -> None:
    path = _recording(recordings, kind)
    found, tl = views(path), timeline(path)
    assert len(found) >= 4, [v.name for v in found]
    for view in found:
        shown = resolve(view, path, timeline=tl)
        assert shown, f"{kind}: panel {view.name!r} ({view.kind}, {view.query}) shows nothing"
        for rule in explicit_rules(view):  # a listed entity must exist and hold data
            one = View(kind=view.kind, name=view.name, origin="/", query=[rule])
            assert resolve(one, path, timeline=tl), \
                f"{kind}: panel {view.name!r} names {rule}, which is empty"


@pytest.mark.parametrize("kind", FLIGHT_VIEWS)
def test_flight_view_shows_every_series_under_a_short_title(recordings, kind) -> None:
    path = _recording(recordings, kind)
    series = {e for e, ent in load(path, sort_by=None).items() if ent.rows.get("Scalars:scalars")}
    plotted: set[str] = set()
    for view in views(path):
        if view.kind == "TimeSeries":
            if not view.origin.startswith("/live_id"):  # convergence: a legend for 3 series
                assert view.properties.get("PlotLegend:visible") == [False], view.name
            assert len(view.name) <= TITLE_MAX, view.name  # not cut in a small panel
            plotted.update(resolve(view, path, timeline="host_time"))
    assert series and plotted == series


def test_imported_streams_keep_their_names_in_the_entities(recordings) -> None:
    ents = load(recordings["replay cfclient import"], sort_by=None)
    np.testing.assert_allclose(
        ents["/stateEstimate\\+controller/rollRate"].scalars()[:3],
        2.0 * np.cos(0.1 * np.arange(3)), rtol=1e-5)  # CSV text: 6 digits
    titles = {v.name for v in views(recordings["replay cfclient import"])}
    assert {"controller [deg]", "controller [deg/s]", "stateEstimate [m]"} <= titles
    odd = load(recordings["odd names"], sort_by=None)
    assert "/rate\\ gyro\\/raw\\\\1/vbat" in odd  # one part, escaped as Rerun prints it


@pytest.mark.parametrize("kind", ["resid", "identify with residuals"])
def test_residual_panels(recordings, kind) -> None:
    path = recordings[kind]
    assert timeline(path) == "lag"  # the correlations are drawn against the lag
    panels = {v.name: v for v in views(path) if v.kind == "TimeSeries"}
    auto = resolve(panels["gyro.x autocorr"], path, timeline="lag")
    assert auto == [f"/sysid/residuals/gyro.x/autocorr/{leaf}"
                    for leaf in ("lower", "upper", "value")]
    cross = resolve(panels["gyro.x x motor.m1"], path, timeline="lag")
    assert len(cross) == 3 and all("/cross/motor.m1/" in e for e in cross)
    model = sysid.load_model(path.with_name("model.h5"))
    assert set(panels) == {  # per output: its autocorrelation, its correlation with each input
        f"{y} {what}" for y in model.output_names
        for what in ("autocorr", *(f"x {u}" for u in model.input_names))}
    ents = load(path, sort_by="lag")
    band = ents["/sysid/residuals/gyro.x/autocorr/upper"]
    assert band.static["SeriesLines:names"] == ["99% bound"]
    assert ents["/sysid/residuals/gyro.x/autocorr/value"].scalars()[0] == pytest.approx(1.0)


def _by_name(path: Path) -> dict[str, View]:
    return {v.name: v for v in views(path)}


def _simulation_slug(path: Path) -> str:
    """The entity name of the simulation mode ``identify`` chose (compare's default: whole
    records, or windows when a pole is near z = 1)."""
    slugs = {v.origin.removeprefix("/sysid/") for v in views(path) if v.name == "gyro.x"
             and v.origin in ("/sysid/simulation", "/sysid/windowed_simulation")}
    assert len(slugs) == 1, slugs
    return slugs.pop()


def test_identification_report_panels(recordings) -> None:
    path = recordings["identify"]
    ents = load(path, sort_by=None)
    by_name = _by_name(path)
    # measured and model of every output channel, not an empty plot
    sim = _simulation_slug(path)  # "simulation" (whole records) or in windows: as compare's
    gyro_x = [resolve(v, path, timeline="t") for v in views(path)
              if v.name == "gyro.x" and v.origin == f"/sysid/{sim}"]
    assert gyro_x[0] == [f"/sysid/{sim}/exp0/gyro.x/measured", f"/sysid/{sim}/exp0/gyro.x/model"]
    # the chosen order is drawn over the singular values; the log chart starts at 0
    bars = resolve(by_name["singular values (order in red)"], path)
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


def test_validation_panels_show_the_validation_flight(recordings) -> None:
    """identify --validate: a tab and a fit text per mode for each data set, the
    identification's on /sysid/<mode>, the validation's on /sysid/validation/<mode>."""
    path = recordings["identify with validation"]
    found = views(path)
    for base in ("/sysid", "/sysid/validation"):
        for slug in (_simulation_slug(path), "prediction_1_step"):
            plot = [v for v in found if v.name == "gyro.x" and v.origin == f"{base}/{slug}"]
            assert len(plot) == 1, [(v.name, v.origin) for v in found]
            assert resolve(plot[0], path, timeline="t") == [
                f"{base}/{slug}/exp0/gyro.x/measured", f"{base}/{slug}/exp0/gyro.x/model"]
    texts = {v.name: v.origin for v in found if v.kind == "TextDocument"}
    sim = _simulation_slug(path)
    assert texts[f"{sim} fit"] == f"/sysid/{sim}/summary"
    assert texts[f"validation {sim} fit"] == f"/sysid/validation/{sim}/summary"
    assert timeline(path) == "t"


def test_the_blueprint_sent_last_is_the_one_read(tmp_path) -> None:
    """Each send_blueprint writes a store of its own and activates it: the viewer shows the
    last; the helpers read that one (store ids are random: several files)."""
    for i in range(6):
        rec, _ = viz.open_recording(name="two", mode="save", rrd_path=tmp_path / f"{i}.rrd")
        rec.log("/a", rr.TextDocument("a"), static=True)
        for name in ("first", "second"):
            rec.send_blueprint(rrb.Blueprint(rrb.TextDocumentView(origin="/a", name=name)))
        viz.close_file(rec, tmp_path / f"{i}.rrd")
        assert [v.name for v in views(tmp_path / f"{i}.rrd")] == ["second"]
