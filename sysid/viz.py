"""Identification results in Rerun: order selection, poles, model vs data, horizon sweeps.

The only module of :mod:`sysid` that talks to Rerun. Every ``log_*`` function writes to a
``rerun.RecordingStream`` (from :func:`open_recording`) under an entity prefix:

===================================  ===========================================================
entity                               content
===================================  ===========================================================
``<p>/order/singular_values``        bar chart of :math:`\\sigma_1 \\ge \\dots \\ge \\sigma_r`
                                     (abscissa 1..r); ``.../log10`` the same as
                                     :math:`\\log_{10}\\sigma_i` (the thesis' Figure 5.1 is
                                     semi-log); ``.../order`` the chosen order as text
``<p>/poles/A``                      eigenvalues of A as 2-D points :math:`(\\Re p, \\Im p)`
``<p>/poles/A_minus_KC``             one-step predictor poles, eig(A - K C)
``<p>/poles/unit_circle``            :math:`|z| = 1`
``<p>/<mode>/exp<e>/<y>/measured``   measured output channel ``y`` of experiment ``e``
``<p>/<mode>/exp<e>/<y>/model``      simulated or k-step predicted output; the series name
                                     carries the fit, ``model (fit 93.21 %)``
``<p>/<mode>/summary``               :meth:`sysid.CompareResult.summary` text
``<p>/sweep/poles/order_<n>``        poles of every order-n model of a horizon sweep, drawn
                                     translucent so dense regions look darker (Figure 5.2)
===================================  ===========================================================

``<mode>`` is ``simulation``, ``windowed_simulation`` or ``prediction_<k>_step``. Model-vs-data
series use the timeline ``t`` (seconds, :math:`t_k = k\\,\\Delta t` from each record's start).
Pole positions are stored as :math:`(\\Re p, \\Im p)`; a static transform on ``<p>/poles`` and
``<p>/sweep/poles`` flips the 2-D view's downward y axis so the imaginary axis points up.
The fit is the NRMSE fit of :func:`sysid.fit_percent`:
:math:`100\\,(1 - \\lVert y - \\hat y\\rVert / \\lVert y - \\bar y\\rVert)`.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from urllib.parse import quote

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from sysid.comparison import CompareResult
from sysid.errors import ParameterError
from sysid.model import StateSpaceModel
from sysid.sweep import SweepResult

__all__ = [
    "MODES",
    "has_display",
    "identification_blueprint",
    "log_compare",
    "log_identification",
    "log_poles",
    "log_singular_values",
    "log_sweep_poles",
    "mode_slug",
    "open_recording",
]

log = logging.getLogger(__name__)

MODES = ("rerun", "serve", "save")
"""``rerun``: native viewer (web viewer without a display); ``serve``: web viewer on
localhost; ``save``: write an ``.rrd`` file."""

WEB_PORT = 9090
_ANGLE = np.linspace(0.0, 2.0 * np.pi, 181)
_CIRCLE = np.column_stack([np.cos(_ANGLE), np.sin(_ANGLE)])
_FLIP_Y = rr.Transform3D(scale=[1.0, -1.0, 1.0])


def has_display() -> bool:
    """True when a native viewer can open a window (Linux: ``DISPLAY``/``WAYLAND_DISPLAY``)."""
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def open_recording(
    *,
    name: str,
    mode: str,
    rrd_path: Path | None = None,
    application_id: str = "cf-sysid",
) -> tuple[rr.RecordingStream, str | None]:
    """A new recording named ``name`` sent to a viewer or file; returns ``(recording, url)``.

    ``mode`` is one of :data:`MODES`. ``"rerun"`` spawns the native viewer when there is a
    display and otherwise serves the web viewer (logged warning). ``url`` is the web viewer's
    address for ``serve`` (also logged), else None. ``"save"`` needs ``rrd_path`` (its folder
    is created; an existing file is replaced).
    """
    if mode not in MODES:
        raise ParameterError(f"view mode {mode!r} is unknown; use one of {', '.join(MODES)}")
    if mode == "save" and rrd_path is None:
        raise ParameterError("view mode 'save' needs rrd_path; pass the .rrd file to write")
    rec = rr.RecordingStream(application_id, recording_id=None)
    rec.send_recording_name(name)
    if mode == "save":
        path = Path(rrd_path)  # type: ignore[arg-type]
        path.parent.mkdir(parents=True, exist_ok=True)
        rec.save(path)
        log.info("writing Rerun recording to %s", path)
        return rec, None
    if mode == "rerun":
        if has_display():
            rec.spawn()
            return rec, None
        log.warning("no display (DISPLAY/WAYLAND_DISPLAY unset): serving the web viewer instead")
    grpc = rec.serve_grpc()
    rr.serve_web_viewer(web_port=WEB_PORT, open_browser=False, connect_to=grpc)
    url = f"http://localhost:{WEB_PORT}/?url={quote(grpc, safe='')}"
    log.warning("Rerun web viewer: %s", url)
    return rec, url


def mode_slug(result: CompareResult) -> str:
    """Entity-path name of a comparison: simulation, windowed_simulation, prediction_<k>_step."""
    if result.horizon is not None:
        return f"prediction_{result.horizon}_step"
    return "simulation" if result.window is None else "windowed_simulation"


def _names(result: CompareResult) -> tuple[str, ...]:
    return result.output_names or tuple(f"y{j}" for j in range(result.fit.size))


def log_singular_values(
    *, rec: rr.RecordingStream, values: np.ndarray, order: int | None = None,
    prefix: str = "sysid",
) -> None:
    """Singular values ``(r,)`` for order selection, linear and log10, and the chosen order.

    A gap after :math:`\\sigma_n` (a large :math:`\\sigma_n / \\sigma_{n+1}`) suggests order n.
    """
    sv = np.asarray(values, dtype=float).reshape(-1)
    index = np.arange(1, sv.size + 1, dtype=float)
    base = f"{prefix}/order/singular_values"
    rec.log(base, rr.BarChart(sv, abscissa=index), static=True)
    with np.errstate(divide="ignore"):
        rec.log(f"{base}/log10", rr.BarChart(np.log10(sv), abscissa=index), static=True)
    if order is not None:
        ratio = sv[order - 1] / sv[order] if 0 < order < sv.size and sv[order] > 0 else np.inf
        rec.log(f"{prefix}/order/order", rr.TextDocument(
            f"order n = {order}: sigma_n = {sv[order - 1]:.4g}, "
            f"sigma_n / sigma_(n+1) = {ratio:.3g}"), static=True)


def _pole_points(poles: np.ndarray) -> np.ndarray:
    """Complex poles (n,) as (n, 2) positions ``(Re, Im)``."""
    p = np.asarray(poles, dtype=complex).reshape(-1)
    return np.column_stack([p.real, p.imag])


def log_poles(*, rec: rr.RecordingStream, model: StateSpaceModel, prefix: str = "sysid") -> None:
    """Poles of ``model`` (eig A, and eig(A - KC) of its predictor) with the unit circle."""
    base = f"{prefix}/poles"
    rec.log(base, _FLIP_Y, static=True)
    rec.log(f"{base}/unit_circle", rr.LineStrips2D([_CIRCLE], colors=[128, 128, 128]),
            static=True)
    for entity, poles, color in (("A", model.poles(), (230, 80, 40)),
                                 ("A_minus_KC", model.predictor_poles(), (40, 120, 230))):
        labels = [f"|p| = {abs(p):.3f}" for p in poles]
        rec.log(f"{base}/{entity}", rr.Points2D(_pole_points(poles), radii=0.02, colors=color,
                                                labels=labels), static=True)


def log_compare(
    *, rec: rr.RecordingStream, result: CompareResult, dt: float,
    units: Sequence[str] | None = None, prefix: str = "sysid",
) -> None:
    """Measured vs simulated or predicted outputs, one entity pair per experiment and channel.

    ``dt`` is the sample period (s); ``units`` (l,) label the series (default: none). The fit
    of experiment e, channel j (``result.fits[e, j]``) is in the model series' name.
    """
    slug = mode_slug(result)
    names = _names(result)
    units = list(units) if units is not None else [""] * len(names)
    for e, (y, yh) in enumerate(zip(result.y_measured, result.y_model, strict=True)):
        time = [rr.TimeColumn("t", duration=np.arange(len(y)) * dt)]
        for j, name in enumerate(names):
            unit = f" [{units[j]}]" if units[j] else ""
            base = f"{prefix}/{slug}/exp{e}/{name}"
            fit = float(result.fits[e, j])
            for leaf, values, label in (("measured", y[:, j], f"measured{unit}"),
                                        ("model", yh[:, j], f"model{unit} (fit {fit:.2f} %)")):
                rec.log(f"{base}/{leaf}", rr.SeriesLines(names=label), static=True)
                rec.send_columns(f"{base}/{leaf}", indexes=time,
                                 columns=rr.Scalars.columns(scalars=values))
    rec.log(f"{prefix}/{slug}/summary", rr.TextDocument(result.summary()), static=True)


def log_sweep_poles(
    *, rec: rr.RecordingStream, result: SweepResult, orders: Sequence[int] | None = None,
    prefix: str = "sysid", alpha: int = 40,
) -> dict[int, int]:
    """Pole clouds of a horizon sweep, one entity per model order (thesis Figure 5.2).

    Every successful row's poles are drawn with opacity ``alpha`` (0-255) so regions where
    many horizon pairs put a pole look darker. Returns ``{order: number of models drawn}``.
    """
    base = f"{prefix}/sweep/poles"
    rec.log(base, _FLIP_Y, static=True)
    rec.log(f"{base}/unit_circle", rr.LineStrips2D([_CIRCLE], colors=[128, 128, 128]),
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
        rec.log(f"{base}/order_{n}", rr.Points2D(pts, radii=0.01, colors=[20, 20, 20, alpha]),
                static=True)
    rec.log(f"{prefix}/sweep/table", rr.TextDocument(result.table()), static=True)
    return counts


def identification_blueprint(
    *, prefix: str = "sysid", comparisons: Sequence[tuple[str, Sequence[str]]] = (),
) -> rrb.Blueprint:
    """Default layout: singular values, poles and sweep clouds on top; below, one tab per
    comparison ``(mode slug, output names)`` with one plot per output channel (all
    experiments), next to the fit summaries."""
    top = rrb.Grid(
        rrb.BarChartView(origin=f"/{prefix}/order/singular_values", contents="$origin",
                         name="singular values"),
        rrb.BarChartView(origin=f"/{prefix}/order/singular_values/log10",
                         name="log10 singular values"),
        # Origins above the y-flipping transforms, so that the flip applies.
        rrb.Spatial2DView(origin=f"/{prefix}", contents="$origin/poles/**",
                          name="poles: A (red), A-KC (blue)"),
        rrb.Spatial2DView(origin=f"/{prefix}/sweep", contents="$origin/poles/**",
                          name="sweep pole clouds"))
    texts = rrb.Vertical(
        rrb.TextDocumentView(origin=f"/{prefix}/order/order", name="order"),
        *[rrb.TextDocumentView(origin=f"/{prefix}/{slug}/summary", name=f"{slug} fit")
          for slug, _ in comparisons])
    tabs = [rrb.Grid(*[rrb.TimeSeriesView(origin=f"/{prefix}/{slug}",
                                          contents=f"$origin/*/{name}/**", name=name)
                       for name in names], name=slug.replace("_", " "))
            for slug, names in comparisons]
    bottom = rrb.Horizontal(rrb.Tabs(*tabs), texts, column_shares=[3, 1]) if tabs else texts
    return rrb.Blueprint(rrb.Vertical(top, bottom), rrb.TimePanel(timeline="t"))


def log_identification(
    *,
    rec: rr.RecordingStream,
    model: StateSpaceModel,
    comparisons: Sequence[CompareResult] = (),
    sweep: SweepResult | None = None,
    singular_values: np.ndarray | None = None,
    prefix: str = "sysid",
) -> None:
    """Everything about one identified model, with a default layout.

    Singular values default to ``model.provenance["singular_values"]`` (order = the model's);
    each comparison (from :func:`sysid.compare` with data sampled at ``model.dt``) gets its own
    tab; a sweep adds its pole clouds.
    """
    sv = singular_values if singular_values is not None else \
        model.provenance.get("singular_values")
    if sv is not None:
        log_singular_values(rec=rec, values=np.asarray(sv), order=model.n_states, prefix=prefix)
    log_poles(rec=rec, model=model, prefix=prefix)
    units = list(model.output_units) if model.output_units else None
    for res in comparisons:
        log_compare(rec=rec, result=res, dt=model.dt, units=units, prefix=prefix)
    if sweep is not None:
        log_sweep_poles(rec=rec, result=sweep, prefix=prefix)
    tabs = {mode_slug(r): _names(r) for r in comparisons}
    rec.send_blueprint(identification_blueprint(prefix=prefix, comparisons=list(tabs.items())))
