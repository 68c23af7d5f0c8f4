"""Read an .rrd file back into plain Python for the viz tests (rerun 0.41 ``RrdReader``)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
from rerun.chunk import RrdReader

__all__ = ["Entity", "blueprint_entities", "load"]


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


def blueprint_views(path: Path) -> dict[str, list[str]]:
    """Display name of every named view of the file's blueprint -> its content queries."""
    reader = RrdReader(path)
    names: dict[str, str] = {}
    queries: dict[str, list[str]] = {}
    for b in reader.blueprints():
        for c in reader.stream(store=b).to_chunks():
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
    reader = RrdReader(path)
    found: dict[str, View] = {}
    extra: dict[str, dict[str, object]] = {}
    for b in reader.blueprints():
        for c in reader.stream(store=b).to_chunks():
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


def _rule(rule: str, origin: str) -> tuple[bool, str, bool]:
    """``(include, path, recursive)`` of one rule line (``+ p``, ``- p`` or ``p``)."""
    rule = rule.strip()
    include = not rule.startswith("-")
    rule = rule.lstrip("+-").strip().replace("$origin", origin.rstrip("/") or "")
    recursive = rule.endswith("/**") or rule == "**"
    path_ = rule[:-3] if rule.endswith("/**") else rule
    if "*" in path_:
        raise AssertionError(f"rule {rule!r}: Rerun supports '*' only as a trailing '/**'")
    path_ = "/" + path_.strip("/")
    return include, path_, recursive


def resolve(view: View, entities: dict[str, Entity]) -> list[str]:
    """Entities of ``entities`` that ``view``'s query selects and that hold something the view
    can draw, by Rerun's rules (EntityPathFilter: the most specific matching rule wins, an
    exact path beats ``/**``; the last of equally specific rules wins; no rule: excluded)."""
    rules = [_rule(r, view.origin) for r in view.query if r.strip()]
    shown = []
    for name, ent in entities.items():
        best: tuple[int, int, int] | None = None
        verdict = False
        for k, (include, path_, recursive) in enumerate(rules):
            if name == path_ or (recursive and (path_ == "/" or name.startswith(path_ + "/"))):
                rank = (path_.count("/") + (path_ != "/"), 0 if recursive else 1, k)
                if best is None or rank > best:
                    best, verdict = rank, include
        if verdict and any(c in ent.static or ent.rows.get(c) for c in _SHOWS[view.kind]):
            shown.append(name)
    return sorted(shown)


def explicit_entities(view: View) -> list[str]:
    """Entities a view names one by one (include rules without ``/**``)."""
    return [p for inc, p, rec in (_rule(r, view.origin) for r in view.query) if inc and not rec]
