"""Identification results in Rerun: order selection, poles, model vs data, horizon sweeps.

The only module of :mod:`sysid` that talks to Rerun. Every ``log_*`` function writes to a
``rerun.RecordingStream`` (from :func:`open_recording`) under an entity prefix:

===================================  ===========================================================
entity                               content
===================================  ===========================================================
``<p>/order/singular_values``        bar chart of :math:`\\sigma_1 \\ge \\dots \\ge \\sigma_r`
                                     (abscissa 1..r, grey); ``.../chosen`` the first n again in
                                     red (the chosen order); ``.../log10`` (and its ``chosen``)
                                     :math:`\\log_{10}(\\sigma_i / \\sigma_{min})`, the thesis'
                                     semi-log Figure 5.1 with every bar rising from 0;
                                     ``.../order`` the chosen order as text
``<p>/poles/A``                      eigenvalues of A as 2-D points :math:`(\\Re p, \\Im p)`,
                                     labelled ``A1``, ``A2``, ... (rows of the pole table)
``<p>/poles/A_minus_KC``             one-step predictor poles, eig(A - K C), ``K1``, ...
``<p>/poles/table``                  both pole tables (:mod:`sysid.pole_format`), Markdown
``<p>/poles/unit_circle``            :math:`|z| = 1`
``<p>/<mode>/exp<e>/<y>/measured``   measured output channel ``y`` of experiment ``e``
``<p>/<mode>/exp<e>/<y>/model``      simulated or k-step predicted output; the series name
                                     carries the fit, ``model (fit 93.21 %)``
``<p>/<mode>/summary``               :meth:`sysid.CompareResult.summary` text
``<p>/validation/<mode>/...``        the same for the validation data (``exp<e>`` its
                                     experiments), apart from the identification data's
``<p>/sweep/poles/order_<n>``        poles of every order-n model of a horizon sweep, drawn
                                     translucent so dense regions look darker (Figure 5.2)
``<p>/residuals/<y>/...``            residual correlations and bands (:func:`log_residuals`)
===================================  ===========================================================

``<mode>`` is ``simulation``, ``windowed_simulation`` or ``prediction_<k>_step``; a channel name
``<y>`` is one escaped path part (:func:`cfcommon.rerun.entity_path`). Model-vs-data series use
the timeline ``t`` (seconds, :math:`t_k = k\\,\\Delta t` from each record's start), so
each data set has entities of its own: one entity never holds two records' samples.
Pole positions are stored as :math:`(\\Re p, \\Im p)`; a static transform on ``<p>/poles`` and
``<p>/sweep/poles`` flips the 2-D view's downward y axis so the imaginary axis points up.
The fit is the NRMSE fit of :func:`sysid.fit_percent`:
:math:`100\\,(1 - \\lVert y - \\hat y\\rVert / \\lVert y - \\bar y\\rVert)`.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

import cfcommon.rerun as rerun_io
from cfcommon.rerun import MODES, WEB_PORT, entity_path, has_display, panel_title
from sysid.comparison import CompareResult
from sysid.errors import ParameterError
from sysid.model import StateSpaceModel
from sysid.pole_format import POLE_COLUMNS, pole_cells, pole_rows, sorted_poles
from sysid.residuals import ResidualResult
from sysid.sweep import SweepResult

__all__ = [
    "MODES",
    "close_file",
    "discard_file",
    "has_display",
    "identification_blueprint",
    "log_compare",
    "log_identification",
    "log_poles",
    "log_residuals",
    "log_singular_values",
    "log_sweep_poles",
    "mode_slug",
    "open_recording",
]

log = logging.getLogger(__name__)

_ANGLE = np.linspace(0.0, 2.0 * np.pi, 181)
_CIRCLE = np.column_stack([np.cos(_ANGLE), np.sin(_ANGLE)])
_FLIP_Y = rr.Transform3D(scale=[1.0, -1.0, 1.0])
_NO_LEGEND = rrb.PlotLegend(visible=False)
_GREY, _RED, _BLUE = (150, 150, 150), (230, 80, 40), (40, 120, 230)
VALIDATION = "validation"
"""Entity-path level of the comparisons on validation data: ``<prefix>/validation/<mode>``."""
ZOOM = ((0.7, 1.1), (-0.2, 0.2))
"""Re and Im ranges of the zoomed pole view: a quadrotor's poles crowd near z = 1."""


def open_recording(
    *,
    name: str,
    mode: Literal["rerun", "serve", "save"],
    rrd_path: Path | None = None,
    application_id: str = "cf-sysid",
    web_port: int = WEB_PORT,
) -> tuple[rr.RecordingStream, str | None]:
    """:func:`cfcommon.rerun.open_recording`; an unknown mode or a busy port is a
    :class:`ParameterError`."""
    try:
        return rerun_io.open_recording(name=name, mode=mode, rrd_path=rrd_path,
                                       application_id=application_id, web_port=web_port)
    except rerun_io.ViewModeError as exc:
        raise ParameterError(str(exc)) from None


def close_file(rec: rr.RecordingStream, path: Path) -> None:
    """:func:`cfcommon.rerun.close_file`: write and close a saved recording; a file that could
    not be written (removed) is a one-line :class:`ParameterError`."""
    try:
        rerun_io.close_file(rec, path)
    except rerun_io.RecordingFileError as exc:
        raise ParameterError(str(exc)) from None


def discard_file(rec: rr.RecordingStream) -> None:
    """:func:`cfcommon.rerun.discard_file`: a saved recording dropped, no file written."""
    rerun_io.discard_file(rec)


def mode_slug(result: CompareResult) -> str:
    """Entity-path name of a comparison: simulation, windowed_simulation, prediction_<k>_step."""
    if result.horizon is not None:
        return f"prediction_{result.horizon}_step"
    return "simulation" if result.window is None else "windowed_simulation"


def _names(result: CompareResult) -> tuple[str, ...]:
    return result.output_names or tuple(f"y{j}" for j in range(result.fit.size))


def _path(prefix: str, *parts: object) -> str:
    """``/<prefix>/<parts...>``, each part (a channel name, ``gyro.x``) escaped as Rerun
    prints it (:func:`cfcommon.rerun.entity_path`), in what is logged and what a layout names."""
    return entity_path(*parts, base=prefix)


def log_singular_values(
    *, rec: rr.RecordingStream, values: np.ndarray, order: int | None = None,
    prefix: str = "sysid",
) -> None:
    """Singular values ``(r,)`` for order selection, linear and log, and the chosen order.

    A gap after :math:`\\sigma_n` (a large :math:`\\sigma_n / \\sigma_{n+1}`) suggests order n.
    The first ``order`` bars are drawn again in red over the grey chart (``.../chosen``). The
    log chart shows :math:`\\log_{10}(\\sigma_i / \\sigma_{min})`, decades above the smallest
    positive value, so every bar rises from 0 (a chart of :math:`\\log_{10}\\sigma_i` would hang
    bars below 1 down from 0).
    """
    sv = np.asarray(values, dtype=float).reshape(-1)
    index = np.arange(1, sv.size + 1, dtype=float)
    base = _path(prefix, "order", "singular_values")
    positive = sv[sv > 0]
    floor = positive.min() if positive.size else 1.0
    with np.errstate(divide="ignore"):
        decades = np.log10(np.maximum(sv, floor) / floor)
    rec.log(base, rr.BarChart(sv, abscissa=index, color=_GREY), static=True)
    rec.log(_path(base, "log10"), rr.BarChart(decades, abscissa=index, color=_GREY), static=True)
    if order is not None and 0 < order <= sv.size:
        rec.log(_path(base, "chosen"), rr.BarChart(sv[:order], abscissa=index[:order], color=_RED),
                static=True)
        rec.log(_path(base, "log10", "chosen"), rr.BarChart(decades[:order], abscissa=index[:order],
                                                    color=_RED), static=True)
    if order is not None:
        ratio = sv[order - 1] / sv[order] if 0 < order < sv.size and sv[order] > 0 else np.inf
        rec.log(_path(prefix, "order", "order"), rr.TextDocument(
            f"order n = {order}: sigma_n = {sv[order - 1]:.4g}, "
            f"sigma_n / sigma_(n+1) = {ratio:.3g}"), static=True)


def _pole_points(poles: np.ndarray) -> np.ndarray:
    """Complex poles (n,) as (n, 2) positions ``(Re, Im)``."""
    p = np.asarray(poles, dtype=complex).reshape(-1)
    return np.column_stack([p.real, p.imag])


def log_poles(*, rec: rr.RecordingStream, model: StateSpaceModel, prefix: str = "sysid") -> None:
    """Poles of ``model`` (eig A, and eig(A - KC) of its predictor) with the unit circle.

    Points are labelled by their row in the pole table (``<p>/poles/table``, the formatter of
    :mod:`sysid.pole_format`): ``A1``, ``A2``, ... and ``K1``, ... for the predictor, short
    enough not to pile up near z = 1 (the zoomed view separates them)."""
    base = _path(prefix, "poles")
    rec.log(base, _FLIP_Y, static=True)
    rec.log(_path(base, "unit_circle"), rr.LineStrips2D([_CIRCLE], colors=[128, 128, 128]),
            static=True)
    texts = []
    for entity, tag, poles, color, title in (
            ("A", "A", model.poles(), _RED, "poles of A"),
            ("A_minus_KC", "K", model.predictor_poles(), _BLUE, "predictor poles, eig(A - KC)")):
        ordered = sorted_poles(poles)
        labels = [f"{tag}{i + 1}" for i in range(ordered.size)]
        rec.log(_path(base, entity), rr.Points2D(_pole_points(ordered), radii=0.01, colors=color,
                                                 labels=labels), static=True)
        rows = pole_cells(pole_rows(ordered, dt=model.dt))
        texts.append(f"{title} (labels {tag}1...):\n\n" + _markdown_table(
            POLE_COLUMNS, [(f"{tag}{r[0]}", *r[1:]) for r in rows]))
    rec.log(_path(base, "table"), rr.TextDocument("\n\n".join(texts),
                                                media_type=rr.MediaType.MARKDOWN), static=True)


def _markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    def row(cells: Sequence[str]) -> str:
        return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"
    lines = [row(header), "|" + "---|" * len(header), *(row(r) for r in rows)]
    return "\n".join(lines)


def log_compare(
    *, rec: rr.RecordingStream, result: CompareResult, dt: float,
    units: Sequence[str] | None = None, prefix: str = "sysid",
) -> None:
    """Measured vs simulated or predicted outputs, one entity pair per experiment and channel.

    ``dt`` is the sample period (s); ``units`` (l,) label the series (default: none). The fit
    of experiment e, channel j (``result.fits[e, j]``) is in the model series' name. The
    entities are ``<prefix>/<mode>/...``: a second result of the same mode under the same
    prefix (another data set) would add its samples to the first's and replace its names
    and summary, so each data set needs its own prefix (:func:`log_identification`'s
    ``validation``).
    """
    slug = mode_slug(result)
    names = _names(result)
    units = list(units) if units is not None else [""] * len(names)
    for e, (y, yh) in enumerate(zip(result.y_measured, result.y_model, strict=True)):
        time = [rr.TimeColumn("t", duration=np.arange(len(y)) * dt)]
        for j, name in enumerate(names):
            unit = f" [{units[j]}]" if units[j] else ""
            base = _path(prefix, slug, f"exp{e}", name)
            fit = float(result.fits[e, j])
            for leaf, values, label in (("measured", y[:, j], f"measured{unit}"),
                                        ("model", yh[:, j], f"model{unit} (fit {fit:.2f} %)")):
                rec.log(_path(base, leaf), rr.SeriesLines(names=label), static=True)
                rec.send_columns(_path(base, leaf), indexes=time,
                                 columns=rr.Scalars.columns(scalars=values))
    rec.log(_path(prefix, slug, "summary"), rr.TextDocument(result.summary()), static=True)


def log_sweep_poles(
    *, rec: rr.RecordingStream, result: SweepResult, orders: Sequence[int] | None = None,
    prefix: str = "sysid", alpha: int = 40,
) -> dict[int, int]:
    """Pole clouds of a horizon sweep, one entity per model order (thesis Figure 5.2).

    Every successful row's poles are drawn with opacity ``alpha`` (0-255) so regions where
    many horizon pairs put a pole look darker. Returns ``{order: number of models drawn}``.
    """
    base = _path(prefix, "sweep", "poles")
    rec.log(base, _FLIP_Y, static=True)
    rec.log(_path(base, "unit_circle"), rr.LineStrips2D([_CIRCLE], colors=[128, 128, 128]),
            static=True)
    ok = [r for r in result.rows if r.error is None]
    wanted = sorted({r.order for r in ok}) if orders is None else [int(n) for n in orders]
    counts = {}
    for n in wanted:
        rows = [r for r in ok if r.order == n]
        counts[n] = len(rows)
        if not rows:
            continue
        pts = np.vstack([_pole_points(r.poles) for r in rows])
        rec.log(_path(base, f"order_{n}"), rr.Points2D(pts, radii=0.01, colors=[20, 20, 20, alpha]),
                static=True)
    rec.log(_path(prefix, "sweep", "table"), rr.TextDocument(result.table()), static=True)
    return counts


def identification_blueprint(
    *, prefix: str = "sysid",
    comparisons: Sequence[tuple[str, Sequence[str], int]] = (),
    sweep: bool = False, singular_values: bool = True, poles: bool = True,
    residuals: tuple[Sequence[str], Sequence[str]] | None = None,
    validation: Sequence[tuple[str, Sequence[str], int]] = (),
) -> rrb.Blueprint:
    """Default layout: singular values and poles (whole plane, and zoomed near z = 1) on top,
    the sweep's pole clouds when there was a sweep; below, one tab per comparison
    ``(mode slug, output names, number of experiments)`` with one plot per output channel (all
    experiments), then one per ``validation`` comparison (same form, entities under
    ``<prefix>/validation``, tab and fit text named ``validation ...``), and a residual tab
    for ``residuals`` ``(output names, input names)``: per
    output its autocorrelation and its cross-correlation with each input, with their
    confidence bands; next to them the order, the pole table, the fit and residual summaries.
    Only what is asked for gets a panel (none says "No data available"). The time panel shows
    ``t``, or ``lag`` when there are residuals and no comparison (a plot draws against the
    time panel's timeline).

    Paths are escaped (:func:`_path`); contents name entities explicitly or end in ``/**``:
    Rerun matches ``*`` only as a trailing ``/**`` (``$origin/*/q/**`` would match nothing).
    Titles fit :data:`cfcommon.rerun.TITLE_MAX` characters (:func:`cfcommon.rerun.panel_title`).
    """
    sv = _path(prefix, "order", "singular_values")
    top: list[rrb.View] = []
    if singular_values:
        top += [rrb.BarChartView(origin=sv, contents=["$origin", "$origin/chosen"],
                                 name="singular values (order in red)", plot_legend=_NO_LEGEND),
                rrb.BarChartView(origin=_path(sv, "log10"), name="log10(sigma / sigma_min)",
                                 plot_legend=_NO_LEGEND)]
    # Origins above the y-flipping transforms, so that the flip applies.
    pole_rules = ["+ $origin/poles/**", "- $origin/poles/table"]
    (x0, x1), (y0, y1) = ZOOM
    if poles:
        top += [rrb.Spatial2DView(origin=_path(prefix), contents=pole_rules,
                                  name="poles: A red, A-KC blue"),
                rrb.Spatial2DView(origin=_path(prefix), contents=pole_rules,
                                  name="poles near z = 1",
                                  visual_bounds=rrb.VisualBounds2D(x_range=[x0, x1],
                                                                   y_range=[y0, y1]))]
    if sweep:
        top.append(rrb.Spatial2DView(origin=_path(prefix, "sweep"), contents="$origin/poles/**",
                                     name="sweep pole clouds"))
    texts: list[rrb.View] = []
    if singular_values:
        texts.append(rrb.TextDocumentView(origin=_path(prefix, "order", "order"), name="order"))
    if poles:
        texts.append(rrb.TextDocumentView(origin=_path(prefix, "poles", "table"),
                                          name="pole table"))
    sets = [(_path(prefix), "", comparisons),
            (_path(prefix, VALIDATION), f"{VALIDATION} ", validation)]
    texts += [rrb.TextDocumentView(origin=_path(base, slug, "summary"),
                                   name=f"{label}{slug} fit")
              for base, label, comps in sets for slug, _, _ in comps]
    if sweep:
        texts.append(rrb.TextDocumentView(origin=_path(prefix, "sweep", "table"), name="sweep"))
    tabs = [rrb.Grid(*[rrb.TimeSeriesView(
                origin=_path(base, slug), name=panel_title(name),
                contents=[f"$origin{entity_path(f'exp{e}', name)}/**" for e in range(n_exp)])
                       for name in names], name=label + slug.replace("_", " "))
            for base, label, comps in sets for slug, names, n_exp in comps]
    if residuals is not None:
        tabs.append(rrb.Grid(*_residual_views(prefix=prefix, outputs=residuals[0],
                                              inputs=residuals[1]), name="residuals"))
        texts.append(rrb.TextDocumentView(origin=_path(prefix, "residuals", "summary"),
                                          name="residuals"))
    side = rrb.Tabs(*texts)
    bottom = rrb.Horizontal(rrb.Tabs(*tabs), side, column_shares=[3, 1]) if tabs else side
    timeline = "lag" if residuals is not None and not (comparisons or validation) else "t"
    return rrb.Blueprint(rrb.Vertical(rrb.Grid(*top), bottom) if top else bottom,
                         rrb.TimePanel(timeline=timeline))


def _residual_views(*, prefix: str, outputs: Sequence[str],
                    inputs: Sequence[str]) -> list[rrb.View]:
    """Per output: its autocorrelation, then its cross-correlation with each input."""
    views: list[rrb.View] = []
    for y in outputs:
        views.append(rrb.TimeSeriesView(origin=_path(prefix, "residuals", y, "autocorr"),
                                        name=panel_title(f"{y} autocorr"),
                                        plot_legend=_NO_LEGEND))
        views += [rrb.TimeSeriesView(origin=_path(prefix, "residuals", y, "cross", u),
                                     name=panel_title(f"{y} x {u}"), plot_legend=_NO_LEGEND)
                  for u in inputs]
    return views


def log_identification(
    *,
    rec: rr.RecordingStream,
    model: StateSpaceModel,
    comparisons: Sequence[CompareResult] = (),
    sweep: SweepResult | None = None,
    residuals: ResidualResult | None = None,
    singular_values: np.ndarray | None = None,
    prefix: str = "sysid",
    validation: Sequence[CompareResult] = (),
) -> None:
    """Everything about one identified model, with a default layout.

    Singular values default to ``model.provenance["singular_values"]`` (order = the model's);
    each comparison (from :func:`sysid.compare` with data sampled at ``model.dt``) gets its own
    tab; a sweep adds its pole clouds; a residual analysis (:func:`sysid.residuals`) its tab.
    ``comparisons`` are on one data set (the identification data), ``validation`` on another
    (held-out records), logged under ``<prefix>/validation`` with tabs of their own: the same
    mode on both keeps both. Within each, the modes must differ (a :class:`ParameterError`
    otherwise): the same mode twice would write over itself.
    """
    for what, comps in (("comparisons", comparisons), ("validation", validation)):
        slugs = [mode_slug(r) for r in comps]
        twice = sorted({s for s in slugs if slugs.count(s) > 1})
        if twice:
            raise ParameterError(f"{what}: {', '.join(twice)} given more than once; one "
                                 "result per mode (another data set goes in validation)")
    sv = singular_values if singular_values is not None else \
        model.provenance.get("singular_values")
    if sv is not None:
        log_singular_values(rec=rec, values=np.asarray(sv), order=model.n_states, prefix=prefix)
    log_poles(rec=rec, model=model, prefix=prefix)
    units = list(model.output_units) if model.output_units else None
    for res in comparisons:
        log_compare(rec=rec, result=res, dt=model.dt, units=units, prefix=prefix)
    for res in validation:
        log_compare(rec=rec, result=res, dt=model.dt, units=units,
                    prefix=_path(prefix, VALIDATION))
    if sweep is not None:
        log_sweep_poles(rec=rec, result=sweep, prefix=prefix)
    if residuals is not None:
        log_residuals(rec=rec, result=residuals, prefix=prefix, layout=False)
    def tabs(comps: Sequence[CompareResult]) -> list[tuple[str, tuple[str, ...], int]]:
        return [(mode_slug(r), _names(r), len(r.y_measured)) for r in comps]

    rec.send_blueprint(identification_blueprint(
        prefix=prefix, comparisons=tabs(comparisons), validation=tabs(validation),
        sweep=sweep is not None, singular_values=sv is not None,
        residuals=_residual_names(residuals) if residuals is not None else None))


def _residual_names(result: ResidualResult) -> tuple[tuple[str, ...], tuple[str, ...]]:
    return tuple(result.output_names), tuple(result.input_names)


def _correlation(*, rec: rr.RecordingStream, path: str, label: str, lags: np.ndarray,
                 values: np.ndarray, bound: float, bound_label: str) -> None:
    """``path/value`` (blue) and its band ``path/upper``, ``path/lower`` (grey) over ``lag``."""
    band = np.full(values.shape, bound)
    for leaf, v, name, color in (("value", values, label, _BLUE), ("upper", band, bound_label,
                                  _GREY), ("lower", -band, bound_label, _GREY)):
        rec.log(_path(path, leaf), rr.SeriesLines(names=name, colors=color), static=True)
        rec.send_columns(_path(path, leaf), indexes=[rr.TimeColumn("lag", sequence=lags)],
                         columns=rr.Scalars.columns(scalars=v))


def log_residuals(*, rec: rr.RecordingStream, result: ResidualResult, prefix: str = "sysid",
                  layout: bool = True) -> None:
    """Residual analysis (:func:`sysid.residuals`) on the ``lag`` timeline, as MATLAB's resid.

    Per output ``y``: ``{prefix}/residuals/{y}/autocorr/{value,upper,lower}`` (lags 0..M with
    the band ``+-z/sqrt(N)``) and ``{prefix}/residuals/{y}/cross/{u}/{value,upper,lower}``
    (lags -M..M, positive = past inputs, with the Bartlett band), plus the summary text. The
    correlation is blue, its band grey. ``layout``: also send a layout of just these panels
    (:func:`log_identification` with ``residuals`` lays them out with the model's instead).
    """
    base = _path(prefix, "residuals")
    bound = f"{100 * result.confidence:g}% bound"
    for c, y in enumerate(result.output_names):
        _correlation(rec=rec, path=_path(base, y, "autocorr"), label=f"{y} autocorr",
                     lags=result.lags, values=result.autocorr[:, c], bound=result.auto_bound,
                     bound_label=bound)
        for i, u in enumerate(result.input_names):
            _correlation(rec=rec, path=_path(base, y, "cross", u), label=f"{y} x {u}",
                         lags=result.cross_lags, values=result.crosscorr[:, c, i],
                         bound=float(result.cross_bound[c, i]), bound_label=bound)
    rec.log(_path(base, "summary"), rr.TextDocument(result.summary()), static=True)
    if layout:
        rec.send_blueprint(identification_blueprint(
            prefix=prefix, singular_values=False, poles=False,
            residuals=_residual_names(result)))
