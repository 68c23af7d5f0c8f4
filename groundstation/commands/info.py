"""``groundstation info SESSION...``: what session files hold."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.measure import Measurement
from rich.table import Table

from cfcommon.cli import output_console, output_table, shown_markup, shown_text
from cfsession import Session, SessionError, open_session

__all__ = ["command", "describe", "live_id"]

MAX_PHASE_ROWS = 200
"""Phases listed in the text table (a file of 200 000 phase rows took minutes to lay out);
``--json`` lists them all."""
_FIELDS_MIN_WIDTH = 24
"""Columns the "fields [unit]" column needs to be readable beside the others."""


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
    imported = session.imported
    first = min((float(np.nanmin(st.time)) for st in session.streams.values() if len(st)),
                default=0.0)
    return {
        "path": str(session.path),
        "schema_version": session.schema_version,
        "start": session.meta.get("start_time_iso"),
        "uri": session.meta.get("uri", ""),
        "firmware": session.meta.get("firmware", ""),
        "plan": session.meta.get("plan_name", ""),
        "tag": session.meta.get("tag", ""),
        "software": session.meta.get("software_version", ""),
        # an imported log's time is the firmware's (it starts when the Crazyflie did): its
        # duration is the data's span; a flight's time starts at 0 when it does
        "duration_s": session.duration - first if imported else session.duration,
        "time_s": [first, session.duration],
        "imported": imported,
        "closed_cleanly": session.closed_cleanly,
        "problems": session.problems,
        "streams": streams,
        "phases": [
            {"name": p.name, "kind": p.kind, "start_s": p.start_s, "end_s": p.end_s}
            for p in session.phases()
        ],
        "events": len(session.events()),
        **({"parameters": params} if (params := flown_parameters(session)) else {}),
        **({"live_id": live_id(session)} if "live_id" in session else {}),
        **({"summary": summary} if isinstance(summary := session.json_meta("summary", None),
                                              dict) else {}),
    }


def flown_parameters(session: Session) -> dict[str, Any]:
    """The plan's ``[parameters]`` as flown: ``{name: {"value": v, "was": old}}`` (untrusted
    file: anything else is left out)."""
    raw = session.json_meta("plan_parameters")
    if not isinstance(raw, dict):
        return {}
    return {str(k): v for k, v in raw.items()
            if isinstance(v, dict) and all(finite_number(v.get(x)) for x in ("value", "was"))}


def finite_number(value: object) -> bool:
    """Whether a value read from a file is a number a float holds (not a bool, not NaN or
    infinite, not an integer of 400 digits: ``float()`` of that raises ``OverflowError``)."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return False
    try:
        return math.isfinite(float(value))
    except OverflowError:
        return False


def live_id(session: Session) -> dict[str, Any]:
    """The live identification of a flight (``groundstation fly --live-id``): ``updates``
    (the number recorded), the settings and, for the final model (the last row), its flight
    time, data span, one-step fit and ``poles`` as ``[re, im]`` pairs; the summary's counts
    (skipped, failed updates, the saved model file) and the excitation cut when converged."""
    s = session["live_id"]
    out: dict[str, Any] = {"updates": len(s)}
    out.update({k: v for k, v in s.attrs.items() if k not in ("kind", "description")})
    summary = session.json_meta("summary", {}) or {}
    entry = summary.get("live_id") or {}
    for key in ("skipped", "failed", "dropped_batches", "converged_at_s", "model_file", "error"):
        if key in entry:
            out[key] = entry[key]
    if entry.get("model_file"):
        out["model_path"] = str(session.path.with_name(entry["model_file"]))
    if summary.get("excitation_cut"):
        out["excitation_cut"] = summary["excitation_cut"]
    if len(s):
        row = s.data[-1]
        order = int(row["order"])
        out["final"] = {"t_s": float(row["host_time"]), "final": bool(row["final"]),
                        "span_s": float(row["span_s"]), "n_samples": int(row["n_samples"]),
                        "order": order, "past": int(row["past"]), "future": int(row["future"]),
                        "fit_pct": float(row["fit_pct"]), "max_pole": float(row["max_pole"])}
        out["poles"] = [[float(row[f"pole_re_{i}"]), float(row[f"pole_im_{i}"])]
                        for i in range(1, order + 1) if f"pole_re_{i}" in s.data.dtype.names]
    return out


def _live_id_text(d: dict[str, Any]) -> list[str]:
    lines = [f"live id: {d['updates']} updates ({d.get('skipped', '?')} skipped), order "
             f"{d.get('order', '-')}, past {d.get('past', '-')}, future {d.get('future', '-')}"]
    if "final" in d:
        f = d["final"]
        poles = ", ".join(f"{re:+.4f}{im:+.4f}j" for re, im in d["poles"])
        lines.append(f"  {'final' if f['final'] else 'last'} model at {f['t_s']:.1f} s on "
                     f"{f['span_s']:.1f} s of data: one-step fit {_fmt(f['fit_pct'], '.1f')} %, "
                     f"max |pole| {f['max_pole']:.4f}")
        lines.append(f"  poles {poles}")
    if d.get("model_path"):
        lines.append(f"  model {d['model_path']}")
    if d.get("excitation_cut"):
        c = d["excitation_cut"]
        lines.append(f"  excitation ended at {c['at_s']:.1f} s, {c['skipped_s']:.1f} s early: "
                     f"{c['reason']}")
    return lines


def _summary_text(summary: dict[str, Any]) -> list[str]:
    """The fly command's summary lines for a stored summary; one line if it is malformed (a
    file from elsewhere)."""
    from groundstation.commands.fly import summary_lines

    try:
        return [f"  {line}" for line in summary_lines(summary)[1:]]
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError):
        return ["  (the stored summary is malformed)"]


def _fields_text(fields: dict[str, str]) -> str:
    """``m1 m2 m3 m4: PWM (0-65535)`` when the fields share a unit, else ``x [g], ...``."""
    units = set(fields.values())
    if len(units) == 1 and (unit := units.pop()):
        return f"{' '.join(fields)}: {unit}"
    return ", ".join(f"{k} [{u}]" if u else k for k, u in fields.items())


def _keep_names_whole(table: Table, names: list[str], width: int) -> None:
    """Names in the first column are what the user types (``--inputs``): never cut. The other
    columns give way (a long word in them folds onto the next line rather than ending in
    ``…``); a name too long even for that (beside the narrowest other columns) folds too."""
    for column in table.columns:
        column.overflow = "fold"
    table.columns[0].no_wrap = max(map(len, names), default=0) <= width // 2


def _count(n: int, what: str) -> str:
    return f"{n} {what}{'' if n == 1 else 's'}"


def _fmt(x: float | None, spec: str = ".2f") -> str:
    return "-" if x is None or (isinstance(x, float) and np.isnan(x)) else format(x, spec)


@click.command("info")
@click.argument("sessions", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the description as JSON.")
@click.option("--events", "show_events", is_flag=True, help="Also list every event.")
@click.option("--width", type=click.IntRange(40, 1000), default=None,
              help="Line width [default: the terminal's; piped: as long as a line needs].")
def command(sessions: tuple[Path, ...], as_json: bool, show_events: bool,
            width: int | None) -> None:
    """Show what session files hold: streams, rates, dropped packets, phases.

    Several files are described one after the other (with --json: a list); a file that cannot
    be read is its one-line error in its place, the others are still described, and the exit
    status is then 2.

    \b
    Example:
      groundstation info sessions/prbs-3axis-20261122T100000Z.h5
      groundstation info sessions/*.h5
      groundstation info flight.h5 --json | jq .streams.gyro.dropped
    """
    if len(sessions) == 1:  # its error is the command's own line
        _show(open_session(sessions[0]), as_json=as_json, show_events=show_events, width=width)
        return
    failed, described = 0, []
    for n, path in enumerate(sessions):
        try:
            s = open_session(path)
        except SessionError as exc:
            failed += 1
            click.echo(f"error: {shown_text(exc)}", err=True)
            continue
        if as_json:
            described.append(describe(s))
            continue
        if n:
            click.echo()
        _show(s, as_json=False, show_events=show_events, width=width)
    if as_json:
        click.echo(json.dumps(described, indent=2))
    if failed:
        raise SessionError(f"{failed} of {len(sessions)} files could not be read (above)")


def _show(s: Session, *, as_json: bool, show_events: bool, width: int | None) -> None:
    """One session's description on standard output, as text or JSON."""
    d = describe(s)
    if as_json:
        click.echo(json.dumps(d, indent=2))
        return
    out = output_console(width=width)
    state = "closed cleanly" if d["closed_cleanly"] else \
        "NOT closed cleanly (still being written, or its writer died)"
    if isinstance(d.get("summary"), dict) and d["summary"].get("aborted"):
        state += ", flight ABORTED (its cause is under the flight summary)"
    out.print(f"[bold]{shown_markup(d['path'])}[/] schema {d['schema_version']}, {state}")
    t0, t1 = d["time_s"]
    span = (f"data {t0:.2f} to {t1:.2f} s of firmware time ({d['duration_s']:.2f} s)"
            if d["imported"] else f"duration {d['duration_s']:.2f} s")
    out.print(shown_markup(  # the file's own text: "[/x]" in it is no markup
        f"start {d['start']}  {span}  uri {d['uri'] or '-'}  "
        f"plan {d['plan'] or '-'}{'  tag ' + d['tag'] if d['tag'] else ''}  "
        f"firmware {d['firmware'] or '-'}"
    ))
    rows = [[shown_markup(name), shown_markup(e["kind"]), str(e["rows"]),
             _fmt(e.get("rate_hz"), ".1f"), str(e.get("expected", "-")),
             str(e.get("dropped", "-"))]
            for name, e in d["streams"].items()]
    fields = [shown_markup(_fields_text(e["fields"]) if e["kind"] != "events" else
                     f"level, source, text ({_count(d['events'], 'event')})")
              for e in d["streams"].values()]
    columns = ["stream", "kind", "rows", "rate Hz", "expected", "dropped"]
    table = output_table(*columns, console=out)
    for row in rows:
        table.add_row(*row)
    # the fields in a last column while it gets a readable width, else each under its stream
    beside = out.width - Measurement.get(out, out.options, table).maximum >= _FIELDS_MIN_WIDTH
    if beside:
        table = output_table(*columns, "fields [unit]", console=out)
        for row, text in zip(rows, fields, strict=True):
            table.add_row(*row, text)
    _keep_names_whole(table, [row[0] for row in rows], out.width)
    out.print(table)
    if not beside:
        out.print(shown_markup("fields [unit]:"))
        grid = Table.grid(padding=(0, 1), pad_edge=True)
        grid.add_column()
        grid.add_column()
        for row, text in zip(rows, fields, strict=True):
            grid.add_row(f"{row[0]}:", text)
        _keep_names_whole(grid, [row[0] + ":" for row in rows], out.width)
        out.print(grid)
    if d["phases"]:
        shown = d["phases"][:MAX_PHASE_ROWS]
        phases = output_table("phase", "kind", "start s", "end s", "length s", console=out)
        _keep_names_whole(phases, [shown_markup(p["name"]) for p in shown], out.width)
        for p in shown:
            phases.add_row(
                shown_markup(p["name"]),
                shown_markup(p["kind"]),
                _fmt(p["start_s"]),
                _fmt(p["end_s"]),
                _fmt(p["end_s"] - p["start_s"]),
            )
        out.print(phases)
        if len(d["phases"]) > len(shown):
            out.print(f"... {len(d['phases']) - len(shown)} more phases (--json lists them)")
    if d.get("summary") and not d["imported"]:  # a flight's (an import's is not in fly's words)
        out.print("flight summary, stored when the flight ended (counts to its end: a stream "
                  "silent after a link loss counts as dropped there):")
        for line in _summary_text(d["summary"]):
            out.print(shown_markup(line))
    if d.get("parameters"):
        out.print("firmware parameters for the flight: " + shown_markup(", ".join(
            f"{k} = {v['value']:g} (was {v['was']:g})" for k, v in d["parameters"].items())))
    if "live_id" in d:
        for line in _live_id_text(d["live_id"]):
            out.print(shown_markup(line))
    for problem in d["problems"]:
        out.print(f"[yellow]problem:[/] {shown_markup(problem)}")
    if show_events:
        for e in s.events():
            out.print(shown_markup(f"{e.t:9.3f} {e.level:8s} {e.source:8s} {e.text}"))
    else:
        out.print(f"{d['events']} events (--events lists them)")
