"""The live identification's panels in the flight's Rerun view (``groundstation fly --live-id
--view ...``, ``docs/live-id.md``).

:class:`LiveIdView` observes a :class:`~groundstation.flight.liveid.LiveIdListener`: ``begin``
once (it sends the layout: the flight's panels of :func:`groundstation.live.flight_blueprint`
above a row of live identification panels) and ``update`` after every model update, called on
the listener's worker thread (never the flight runner's). Entities, all under ``/live_id``
(paths built by :func:`cfcommon.rerun.entity_path`):

=====================================  ======================================================
``/live_id/z_plane/unit_circle``       the unit circle (static)
``/live_id/z_plane/poles``             the poles of each update, ``(Re, Im)``; the panel shows
                                       the last :data:`TRAIL_S` seconds of updates (a trail)
``/live_id/singular_values/values``    ``(i, log10 sigma_i)`` of the last update; the first
                                       ``order`` (the chosen ones) orange, the rest grey
``/live_id/singular_values/order``     a vertical line between the chosen and the rest
``/live_id/prediction/<y>/measured``   each output (mean removed) and its one-step-ahead
``/live_id/prediction/<y>/predicted``  prediction by the model of the time, the samples since
                                       the previous update (on ``fw_time`` and ``host_time``)
``/live_id/convergence/<name>``        ``pole_move``, ``innovation_nvar``, ``fit_pct``,
                                       ``max_pole`` per update
``/live_id/status``                    the one-line status of each update (text log)
=====================================  ======================================================
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from cfcommon.rerun import entity_path
from cfsession.schema import StreamSpec

__all__ = ["TRAIL_S", "LiveIdView", "live_id_views", "send_rows"]

log = logging.getLogger(__name__)

TRAIL_S = 10.0
"""Seconds of past updates the pole panel shows (a trail of the poles' way)."""
PREDICTION_S = 5.0
"""Seconds of one-step prediction against measurement shown."""
_BASE = "/live_id"
_CHOSEN, _REST, _MEASURED = (255, 127, 0), (150, 150, 150), (55, 126, 184)
_SERIES = {"pole_move": "pole move [1]", "innovation_nvar": "innov. var [1]",
           "fit_pct": "1-step fit [%]", "max_pole": "max |pole| [1]"}


def _path(*parts: object) -> str:
    return entity_path(*parts, base=_BASE)


def _recent(seconds: float) -> rrb.VisibleTimeRange:
    return rrb.VisibleTimeRange("host_time",
                                start=rrb.TimeRangeBoundary.cursor_relative(seconds=-seconds),
                                end=rrb.TimeRangeBoundary.cursor_relative())


def live_id_views(*, recorded: bool = False) -> rrb.Horizontal:
    """The row of live identification panels (module docstring). ``recorded``: only those a
    replay of the session's ``live_id`` stream fills (:func:`send_rows`: the singular values
    and the predictions are not recorded)."""
    quiet = rrb.PlotLegend(visible=False)
    live_only = [] if recorded else [
        rrb.Spatial2DView(origin=_path("singular_values"), name="singular values"),
        rrb.TimeSeriesView(origin=_path("prediction"), name="1-step prediction",
                           time_ranges=_recent(PREDICTION_S), plot_legend=quiet)]
    return rrb.Horizontal(
        rrb.Spatial2DView(origin=_path("z_plane"), name="poles (z-plane)",
                          time_ranges=_recent(TRAIL_S)),
        *live_only,
        rrb.TimeSeriesView(origin=_path("convergence"), name="convergence",
                           contents=[_path("convergence", n)
                                     for n in ("pole_move", "innovation_nvar", "max_pole")]),
        rrb.TimeSeriesView(origin=_path("convergence"), name="1-step fit [%]",
                           contents=[_path("convergence", "fit_pct")], plot_legend=quiet),
        rrb.TextLogView(origin=_path("status"), name="live id"),
    )


class LiveIdView:
    """Draws a :class:`~groundstation.flight.liveid.LiveIdListener`'s updates into ``rec``
    (module docstring). ``flight_layout=False`` sends the live identification panels alone."""

    def __init__(self, *, rec: rr.RecordingStream, flight_layout: bool = True) -> None:
        self.rec, self.flight_layout = rec, flight_layout
        self._labels: tuple[str, ...] = ()

    def begin(self, *, listener: Any, streams: Sequence[StreamSpec]) -> None:
        """Static parts (unit circle, series styles) and the layout."""
        _log_static(self.rec)
        self._labels = tuple(c.label for c in listener.outputs)
        for label in self._labels:
            self.rec.log(_path("prediction", label, "measured"),
                         rr.SeriesLines(names=f"{label} measured", colors=_MEASURED), static=True)
            self.rec.log(_path("prediction", label, "predicted"),
                         rr.SeriesLines(names=f"{label} 1-step", colors=_CHOSEN), static=True)
        live = live_id_views()
        if self.flight_layout:
            from groundstation.live import flight_blueprint

            flight = flight_blueprint(streams).root_container
            layout = rrb.Vertical(flight, live, row_shares=[2, 1])
        else:
            layout = live
        self.rec.send_blueprint(rrb.Blueprint(layout, rrb.TimePanel(timeline="host_time"),
                                              collapse_panels=True))

    def update(self, *, update: Any) -> None:
        """Log one :class:`~groundstation.flight.liveid.Update` (from the worker thread)."""
        u, rec = update, self.rec
        poles = np.asarray(u.poles)
        _log_update(rec, t=u.t, poles=poles, values={
            "pole_move": u.pole_move, "innovation_nvar": u.innovation_nvar,
            "fit_pct": u.fit_pct, "max_pole": float(np.abs(poles).max())})
        sv = np.asarray(u.singular_values, dtype=float)
        if sv.size:
            idx = np.arange(1, sv.size + 1, dtype=float)
            logs = np.log10(np.maximum(sv, 1e-300))
            colors = [_CHOSEN if i <= u.order else _REST for i in idx]
            rec.log(_path("singular_values", "values"),
                    rr.Points2D(np.column_stack([idx, logs]), radii=0.3, colors=colors))
            x = u.order + 0.5
            rec.log(_path("singular_values", "order"),
                    rr.LineStrips2D([[[x, logs.min()], [x, logs.max()]]], colors=[_REST]))
        rec.log(_path("status"), rr.TextLog(
            f"{'final ' if u.final else ''}update: {u.span_s:.1f} s of data, order {u.order}, "
            f"max |pole| {np.abs(poles).max():.4f}, move {u.pole_move:.1e}, 1-step fit "
            f"{u.fit_pct:.1f} %, innovation var {u.innovation_nvar:.3f}, {u.update_s:.2f} s"))
        self._prediction(u)

    def _prediction(self, u: Any) -> None:
        if not len(u.fw_times):
            return
        times = [rr.TimeColumn("fw_time", duration=u.fw_times),
                 rr.TimeColumn("host_time", duration=u.host_times)]
        for j, label in enumerate(self._labels):
            for kind, values in (("measured", u.measured), ("predicted", u.predicted)):
                self.rec.send_columns(_path("prediction", label, kind), indexes=times,
                                      columns=rr.Scalars.columns(scalars=values[:, j]))


def _log_static(rec: rr.RecordingStream) -> None:
    """The unit circle and the convergence series' names with their units (live and replay)."""
    phi = np.linspace(0.0, 2.0 * np.pi, 181)
    rec.log(_path("z_plane", "unit_circle"),
            rr.LineStrips2D([np.column_stack([np.cos(phi), np.sin(phi)])], colors=[_REST]),
            static=True)
    for name, label in _SERIES.items():
        rec.log(_path("convergence", name), rr.SeriesLines(names=label), static=True)


def _log_update(rec: rr.RecordingStream, *, t: float, poles: np.ndarray,
                values: dict[str, float]) -> None:
    """The poles and the convergence series of one update at flight time ``t``."""
    rec.set_time("host_time", duration=t)
    rec.log(_path("z_plane", "poles"),
            rr.Points2D(np.column_stack([poles.real, poles.imag]), radii=0.015,
                        colors=[_CHOSEN]))
    for name, value in values.items():
        if np.isfinite(value):
            rec.log(_path("convergence", name), rr.Scalars(float(value)))


def send_rows(rec: rr.RecordingStream, data: np.ndarray) -> None:
    """Rows of a recorded ``live_id`` stream (replay): the poles, the convergence series and a
    status line of each update (singular values and predictions are not recorded), each entity
    sent as one block (``send_columns``) on ``host_time``."""
    names = data.dtype.names or ()
    if "order" not in names or "host_time" not in names:
        log.warning("live_id stream without order or host_time: not shown")
        return
    from groundstation.live import MAX_TIME_S

    _log_static(rec)
    t = data["host_time"].astype(np.float64)
    timed = np.isfinite(t) & (np.abs(t) < MAX_TIME_S)
    if not timed.all():  # a file from elsewhere
        log.warning("%d live_id row(s) have no usable host_time: not shown", (~timed).sum())
        data, t = data[timed], t[timed]
    if not len(data):
        return
    ns = np.rint(t * 1e9).astype(np.int64).astype("timedelta64[ns]")  # as rr.set_time rounds
    n, at = len(data), [rr.TimeColumn("host_time", duration=ns)]
    order = data["order"].astype(np.float64)
    positions, counts = _pole_columns(data, order)
    style = rr.Points2D.columns(radii=np.full(n, 0.015, dtype=np.float32),
                                colors=np.tile(np.array(_CHOSEN, np.uint8), (n, 1)))
    rec.send_columns(_path("z_plane", "poles"), indexes=at,
                     columns=[*rr.Points2D.columns(positions=positions).partition(counts), *style])
    values = {k: data[k].astype(np.float64) for k in _SERIES if k in names}
    for name, v in values.items():
        ok = np.isfinite(v)
        if ok.any():
            rec.send_columns(_path("convergence", name),
                             indexes=[rr.TimeColumn("host_time", duration=ns[ok])],
                             columns=rr.Scalars.columns(scalars=v[ok]))
    rec.send_columns(_path("status"), indexes=at,
                     columns=rr.TextLog.columns(text=_status_lines(order, values)))


def _pole_columns(data: np.ndarray, order: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(Re, Im)`` of every row's poles, one after the other, and how many each row has: the
    first ``order`` pole columns the file stores (a file from elsewhere: order 3e9 or NaN)."""
    names = data.dtype.names or ()
    stored = sum(1 for k in names if k.startswith("pole_re_"))
    idx = [i for i in range(1, stored + 1) if f"pole_re_{i}" in names and f"pole_im_{i}" in names]
    if not idx:
        return np.zeros((0, 2)), np.zeros(len(data), dtype=np.int64)
    usable = np.where(np.isfinite(order) & (order >= 0), order, 0.0)
    take = np.array(idx)[None, :] <= np.minimum(usable, stored)[:, None]
    re = np.column_stack([data[f"pole_re_{i}"] for i in idx])
    im = np.column_stack([data[f"pole_im_{i}"] for i in idx])
    positions = np.column_stack([re[take], im[take]])
    return positions, take.sum(axis=1)


def _status_lines(order: np.ndarray, values: dict[str, np.ndarray]) -> list[str]:
    """The status line of each recorded update."""
    columns = {_SERIES[k]: v.tolist() for k, v in values.items()}
    return [f"update (recorded): order {o:g}, " + ", ".join(
        f"{label} {v[i]:.4g}" for label, v in columns.items() if math.isfinite(v[i]))
        for i, o in enumerate(order.tolist())]
