"""The flight view's entity paths and default layout (blueprint), for :mod:`groundstation.live`.

Every path the view logs to and every path the layout names is built by
:func:`cfcommon.rerun.entity_path` from the stream and field names, so a stream named
``stateEstimate+controller`` (an imported uSD log) is ``/stateEstimate\\+controller/<field>``
on both sides.

The layout plots each log stream in its own panels, one per unit, titled ``gyro [deg/s]``;
roll/pitch setpoints (deg) share a panel with ``stabilizer.roll/pitch`` when those are logged,
and the yaw-rate setpoint shares one with ``gyro.z`` (both deg/s). The setpoints and link
streams are found by their kind, whatever their name. Every numeric series is in some panel.
Titles fit :data:`cfcommon.rerun.TITLE_MAX` characters: a stream whose name makes
``stream [unit]`` too long (``stateEstimate+controller [deg/s]``) gets one panel per variable
group and unit instead, ``controller [deg/s]``, ``stateEstimate [m]`` (the entity keeps the
stream's name). No legend (a legend covers a small panel); hovering a line names it.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import rerun.blueprint as rrb

from cfcommon.rerun import TITLE_MAX, entity_path, panel_title
from cfsession.schema import Field, StreamSpec

__all__ = ["EVENTS", "PHASE", "SESSION", "flight_blueprint", "series_fields"]

EVENTS, PHASE, SESSION = entity_path("events"), entity_path("phase"), entity_path("session")
_SKIP = {"host_time", "fw_time_ms", "phase_id", "tick"}
#: Setpoint panels: title, the setpoint fields and the logged variables drawn with them.
_SETPOINT_PANELS = (
    ("roll, pitch [deg]", ("roll", "pitch"), ("stabilizer.roll", "stabilizer.pitch")),
    ("yaw rate [deg/s]", ("yaw_rate",), ("gyro.z",)),
    ("thrust [PWM]", ("thrust",), ()),
)


def series_fields(spec: StreamSpec) -> list[Field]:
    """The fields of ``spec`` shown as scalar series (numeric, not a time or index column)."""
    if spec.kind in ("events", "phases", "live_id"):  # live_id: groundstation.liveid_view
        return []
    return [f for f in spec.fields if f.name not in _SKIP and np.dtype(f.dtype).kind in "fiub"]


def _entity_of(specs: Sequence[StreamSpec], source: str) -> str | None:
    """The entity of the logged variable ``source`` (e.g. ``gyro.z``), if it is logged."""
    for spec in specs:
        for f in spec.fields:
            if spec.kind == "log" and f.source == source:
                return entity_path(spec.name, f.name)
    return None


def _short_unit(unit: str) -> str:
    """``PWM (0-65535)`` -> ``PWM``: panel titles stay short enough for small panels."""
    return unit.split(" (", 1)[0]


def _group(f: Field, default: str) -> str:
    """The variable group ``f`` was logged from: ``controller`` for ``controller.r_roll``."""
    group, dot, _ = f.source.partition(".")
    return group if dot and group else default


def _log_panels(spec: StreamSpec) -> list[tuple[str, list[Field]]]:
    """``(title, fields)`` of the panels of a log stream (module docstring)."""
    by_unit: dict[str, list[Field]] = {}
    for f in series_fields(spec):
        by_unit.setdefault(_short_unit(f.unit), []).append(f)
    panels: list[tuple[str, list[Field]]] = []
    for unit, fields in by_unit.items():
        whole = f"{spec.name} [{unit}]" if unit else spec.name
        if len(whole) <= TITLE_MAX:
            panels.append((whole, fields))
            continue
        by_group: dict[str, list[Field]] = {}
        for f in fields:
            by_group.setdefault(_group(f, spec.name), []).append(f)
        panels += [(panel_title(group, unit=unit), fs) for group, fs in by_group.items()]
    return panels


def _plot(*, name: str, contents: str | list[str], origin: str = "/") -> rrb.TimeSeriesView:
    return rrb.TimeSeriesView(origin=origin, contents=contents, name=panel_title(name),
                              plot_legend=rrb.PlotLegend(visible=False))


def flight_blueprint(streams: Sequence[StreamSpec]) -> rrb.Blueprint:
    """The default layout for these streams (module docstring)."""
    by_kind: dict[str, list[StreamSpec]] = {}
    for s in streams:
        by_kind.setdefault(s.kind, []).append(s)
    plots: list[rrb.View] = []
    placed: set[str] = set()
    for s in by_kind.get("log", []):
        panels = _log_panels(s)
        for title, fields in panels:
            entities = [entity_path(s.name, f.name) for f in fields]
            placed.update(entities)
            plots.append(_plot(origin=entity_path(s.name), name=title,
                               contents="$origin/**" if len(panels) == 1 else entities))
    for s in by_kind.get("setpoints", []):  # by kind: a file made elsewhere may name it so
        axes = {f.name for f in series_fields(s)}
        for title, fields, measured in _SETPOINT_PANELS:
            commanded = [entity_path(s.name, f) for f in fields if f in axes]
            if commanded:  # no panel of measurements alone: they have their own
                contents = commanded + [e for v in measured if (e := _entity_of(streams, v))]
                plots.append(_plot(contents=contents, name=title))
                placed.update(contents)
    for s in by_kind.get("link", []):
        axes = {f.name for f in series_fields(s)}
        for title, field in (("link quality [%]", "quality"), ("latency [ms]", "latency_ms")):
            if field in axes:
                plots.append(_plot(contents=entity_path(s.name, field), name=title))
                placed.add(entity_path(s.name, field))
    for s in streams:  # any other series (a stream kind or field added later): its own panel
        for f in series_fields(s):
            entity = entity_path(s.name, f.name)
            if entity not in placed:
                plots.append(_plot(contents=entity, name=panel_title(
                    f"{s.name}.{f.name}", unit=_short_unit(f.unit))))
    side: list[rrb.View] = []  # only for streams there are: no "No data available" panel
    if "phases" in by_kind:
        side += [rrb.StateTimelineView(origin=PHASE, name="phase"),
                 rrb.TextLogView(origin=PHASE, name="phases")]
    if "events" in by_kind:
        side.insert(1 if side else 0, rrb.TextLogView(origin=EVENTS, name="events"))
    side.append(rrb.TextDocumentView(origin=SESSION, name="session"))
    layout: rrb.Container = rrb.Horizontal(rrb.Grid(*plots), rrb.Vertical(*side),
                                           column_shares=[3, 1])
    if "live_id" in by_kind:  # a recorded live identification (fly --live-id), replayed
        from groundstation.liveid_view import live_id_views

        layout = rrb.Vertical(layout, live_id_views(recorded=True), row_shares=[2, 1])
    return rrb.Blueprint(layout, rrb.TimePanel(timeline="host_time"), collapse_panels=True)
