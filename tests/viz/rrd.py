"""Read an .rrd file back into plain Python for the viz tests (rerun 0.41 ``RrdReader``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

__all__ = ["Entity", "View", "blueprint_entities", "explicit_rules", "load", "resolve",
           "timeline", "views"]


@dataclass
class Entity:
    """Temporal rows of one entity (sorted by ``sort_by``) and its static components."""

    rows: dict[str, list] = field(default_factory=dict)
    times: dict[str, np.ndarray] = field(default_factory=dict)
    static: dict[str, object] = field(default_factory=dict)

    def scalars(self) -> np.ndarray:
        """Scalar values, (n_rows,) for one instance per row, else (n_rows, k)."""
        vals = np.array(self.rows["Scalars:scalars"], dtype=float)
        return vals[:, 0] if vals.ndim == 2 and vals.shape[1] == 1 else vals


def _kind(f: pa.Field) -> str:
    return (f.metadata or {}).get(b"rerun:kind", b"").decode()


def load(path: Path, *, sort_by: str | None = "host_time") -> dict[str, Entity]:
    """Every entity of the file's recording: components per row, timelines in seconds."""
    out: dict[str, Entity] = {}
    raw: dict[str, dict[str, list]] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        rb = chunk.to_record_batch()
        ent = out.setdefault(chunk.entity_path, Entity())
        acc = raw.setdefault(chunk.entity_path, {})
        for f in rb.schema:
            col = rb.column(f.name)
            if _kind(f) == "index":
                acc.setdefault("@" + f.name, []).extend(
                    (col.cast(pa.int64()).to_numpy(zero_copy_only=False) / 1e9).tolist())
            elif _kind(f) == "data":
                values = col.to_pylist()
                if chunk.is_static:
                    ent.static[f.name] = values[-1]
                else:
                    acc.setdefault(f.name, []).extend(values)
    for path_, acc in raw.items():
        ent = out[path_]
        n = max((len(v) for v in acc.values()), default=0)
        order = np.arange(n)
        key = "@" + sort_by if sort_by else None
        if key in acc and len(acc[key]) == n:
            order = np.argsort(np.asarray(acc[key]), kind="stable")
        for k, v in acc.items():
            if len(v) != n:
                continue  # a timeline not on every row of this entity
            if k.startswith("@"):
                ent.times[k[1:]] = np.asarray(v)[order]
            else:
                ent.rows[k] = [v[i] for i in order]
    return out


def blueprint_entities(path: Path) -> list[str]:
    """Entity paths of the file's blueprint store (views, containers, time panel)."""
    reader = RrdReader(path)
    return [c.entity_path for b in reader.blueprints() for c in reader.stream(store=b).to_chunks()]


def _active_blueprint(path: Path) -> list:
    """The blueprint the viewer shows, as a list of its chunks (none: empty).

    Each ``send_blueprint`` writes a blueprint store of its own and makes it active, so of
    several the viewer shows the one sent last: the store whose first message comes last in
    the file (a store's id is in each of its messages)."""
    reader = RrdReader(path)
    data = Path(path).read_bytes()
    stores = reader.blueprints()
    if not stores:
        return []
    last = max(stores, key=lambda b: data.find(b.recording_id.encode()))
    return list(reader.stream(store=last).to_chunks())


def blueprint_views(path: Path) -> dict[str, list[str]]:
    """Display name of every named view of the file's blueprint -> its content queries."""
    names: dict[str, str] = {}
    queries: dict[str, list[str]] = {}
    for c in _active_blueprint(path):
        rb = c.to_record_batch()
        cols = set(rb.schema.names)
        if "ViewBlueprint:display_name" in cols:
            names[c.entity_path] = rb.column("ViewBlueprint:display_name").to_pylist()[-1][0]
        if "ViewContents:query" in cols:
            queries[c.entity_path.rsplit("/", 1)[0]] = rb.column(
                "ViewContents:query").to_pylist()[-1]
    return {name: queries.get(path_, []) for path_, name in names.items()}


# ------------------------------------------------------------------ blueprint resolution
_SHOWS = {  # view class -> components it draws (any one makes an entity visible in it)
    "TimeSeries": ("Scalars:scalars",),
    "BarChart": ("BarChart:values",),
    "2D": ("Points2D:positions", "LineStrips2D:strips"),
    "TextDocument": ("TextDocument:text",),
    "TextLog": ("TextLog:text",),
    "StateTimeline": ("StateChange:state",),
}


@dataclass
class View:
    """One view of a blueprint: class, title, origin, content rules and blueprint properties."""

    kind: str
    name: str
    origin: str
    query: list[str]
    properties: dict[str, object] = field(default_factory=dict)


def views(path: Path) -> list[View]:
    """Every view of the file's blueprint, with its content query (default ``$origin/**``)."""
    found: dict[str, View] = {}
    extra: dict[str, dict[str, object]] = {}
    for c in _active_blueprint(path):
        rb = c.to_record_batch()
        last = {n: rb.column(n).to_pylist()[-1] for n in rb.schema.names if ":" in n}
        if "ViewBlueprint:class_identifier" in last:
            found[c.entity_path] = View(
                kind=last["ViewBlueprint:class_identifier"][0],
                name=(last.get("ViewBlueprint:display_name") or [""])[0],
                origin=(last.get("ViewBlueprint:space_origin") or ["/"])[0],
                query=["$origin/**"])
        else:
            extra.setdefault(c.entity_path.rsplit("/", 1)[0], {}).update(last)
    for path_, view in found.items():
        props = extra.get(path_, {})
        view.query = list(props.pop("ViewContents:query", view.query))
        view.properties = props
    return list(found.values())


def timeline(path: Path) -> str | None:
    """The timeline the blueprint's time panel shows (time series plot against it)."""
    for c in _active_blueprint(path):
        rb = c.to_record_batch()
        if "TimePanelBlueprint:timeline" in rb.schema.names:
            return rb.column("TimePanelBlueprint:timeline").to_pylist()[-1][0]
    return None


def _expressions(view: View) -> list[str]:
    """The view's query with ``$origin`` substituted, as the viewer does before parsing."""
    origin = view.origin if view.origin != "/" else ""
    return [q.replace("$origin", origin) for q in view.query if q.strip()]


def resolve(view: View, path: Path, *, timeline: str | None = None) -> list[str]:
    """Entities of the recording in ``path`` that ``view`` shows: selected by its query under
    Rerun's own entity-path filter (``LazyChunkStream.filter``: forgiving parse and
    unescaping, most specific rule wins, ``*`` only as a trailing ``/**``) and holding a
    component the view draws; for a time series, on ``timeline`` (the time panel's)."""
    rows: dict[str, int] = {}
    stream = RrdReader(path).stream().filter(
        content=_expressions(view), components=list(_SHOWS[view.kind]),
        has_timeline=timeline if view.kind == "TimeSeries" else None)
    for chunk in stream.to_chunks():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    return sorted(e for e, n in rows.items() if n)


def explicit_rules(view: View) -> list[str]:
    """The view's include rules that name one entity (no ``/**``), ``$origin`` substituted."""
    return [r.lstrip("+").strip() for r in _expressions(view)
            if not r.startswith("-") and not r.rstrip().endswith("**")]
