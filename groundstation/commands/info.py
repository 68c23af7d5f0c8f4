"""``groundstation info SESSION``: what a session file holds."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.markup import escape

from cfcommon.cli import output_console, output_table
from cfsession import Session, open_session

__all__ = ["command", "describe"]


def describe(session: Session) -> dict[str, Any]:
    """A JSON-ready description: metadata, per-stream rows/rates/gaps, phases, problems."""
    streams = {}
    for name, s in session.streams.items():
        entry: dict[str, Any] = {
            "kind": s.kind,
            "rows": len(s),
            "fields": {f: session[name].units.get(f, "") for f in s.value_fields},
        }
        if len(s) > 1 and s.kind in ("log", "setpoints", "link"):  # sampled streams only
            span = float(s.time[-1] - s.time[0])
            entry["span_s"] = span
            entry["rate_hz"] = (len(s) - 1) / span if span > 0 else None
        if s.kind == "log" and s.period_s:
            fw = s.fw_time_s
            expected = (
                round((fw[-1] - fw[0]) / s.period_s) + 1 if fw is not None and len(fw) else 0
            )
            entry["period_s"] = s.period_s
            entry["expected"] = expected
            entry["dropped"] = sum(g.missing for g in s.gaps())
            entry["gaps"] = len(s.gaps())
        streams[name] = entry
    return {
        "path": str(session.path),
        "schema_version": session.schema_version,
        "start": session.meta.get("start_time_iso"),
        "uri": session.meta.get("uri", ""),
        "firmware": session.meta.get("firmware", ""),
        "plan": session.meta.get("plan_name", ""),
        "tag": session.meta.get("tag", ""),
        "software": session.meta.get("software_version", ""),
        "duration_s": session.duration,
        "closed_cleanly": session.closed_cleanly,
        "problems": session.problems,
        "streams": streams,
        "phases": [
            {"name": p.name, "kind": p.kind, "start_s": p.start_s, "end_s": p.end_s}
            for p in session.phases()
        ],
        "events": len(session.events()),
    }


def _fields_text(fields: dict[str, str]) -> str:
    """``m1 m2 m3 m4: PWM (0-65535)`` when the fields share a unit, else ``x [g], ...``."""
    units = set(fields.values())
    if len(units) == 1 and (unit := units.pop()):
        return f"{' '.join(fields)}: {unit}"
    return ", ".join(f"{k} [{u}]" if u else k for k, u in fields.items())


def _fmt(x: float | None, spec: str = ".2f") -> str:
    return "-" if x is None or (isinstance(x, float) and np.isnan(x)) else format(x, spec)


@click.command("info")
@click.argument("session", type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the description as JSON.")
@click.option("--events", "show_events", is_flag=True, help="Also list every event.")
@click.option("--width", type=click.IntRange(40, 1000), default=None,
              help="Line width [default: the terminal's; piped: as long as a line needs].")
def command(session: Path, as_json: bool, show_events: bool, width: int | None) -> None:
    """Show what a session file holds: streams, rates, dropped packets, phases.

    \b
    Example:
      groundstation info sessions/prbs-3axis-20261122T100000Z.h5
      groundstation info flight.h5 --json | jq .streams.gyro.dropped
    """
    s = open_session(session)
    d = describe(s)
    if as_json:
        click.echo(json.dumps(d, indent=2))
        return
    out = output_console(width=width)
    state = "closed cleanly" if d["closed_cleanly"] else "NOT closed cleanly (writer died)"
    out.print(f"[bold]{d['path']}[/] schema {d['schema_version']}, {state}")
    out.print(
        f"start {d['start']}  duration {d['duration_s']:.2f} s  uri {d['uri'] or '-'}  "
        f"plan {d['plan'] or '-'}{'  tag ' + d['tag'] if d['tag'] else ''}  "
        f"firmware {d['firmware'] or '-'}"
    )
    table = output_table("stream", "kind", "rows", "rate Hz", "expected", "dropped",
                         "fields [unit]", console=out)
    for name, e in d["streams"].items():
        fields = escape(_fields_text(e["fields"]))
        table.add_row(
            name,
            e["kind"],
            str(e["rows"]),
            _fmt(e.get("rate_hz"), ".1f"),
            str(e.get("expected", "-")),
            str(e.get("dropped", "-")),
            fields,
        )
    out.print(table)
    if d["phases"]:
        phases = output_table("phase", "kind", "start s", "end s", "length s", console=out)
        for p in d["phases"]:
            phases.add_row(
                p["name"],
                p["kind"],
                _fmt(p["start_s"]),
                _fmt(p["end_s"]),
                _fmt(p["end_s"] - p["start_s"]),
            )
        out.print(phases)
    for problem in d["problems"]:
        out.print(f"[yellow]problem:[/] {problem}")
    if show_events:
        for e in s.events():
            out.print(f"{e.t:9.3f} {e.level:8s} {e.source:8s} {e.text}")
    else:
        out.print(f"{d['events']} events (--events lists them)")
