"""``groundstation plan check PLAN`` and ``groundstation plan show PLAN``.

``check`` validates a plan (errors name key and line; exit 2) and prints the phase timeline, the
duration, the setpoint count, for each PRBS its period, clock period and order of persistent
excitation, the altitude hold and live identification the flight uses (defaults named), and
warnings (:func:`groundstation.plan.checks.plan_warnings`, and the PRBS's own); ``show`` draws
the setpoints per axis in the terminal or dumps the schedule as JSON, and prints a designed
plan's notes; ``design`` writes the next flight's plan from an identified
model (:mod:`groundstation.commands.plan_design`). PLAN is a path or the name of a shipped plan
(``flightplans/NAME.toml``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console
from rich.table import Table

from cfcommon.cli import check_output, output_console, shown_markup
from groundstation.commands.plan_design import design
from groundstation.plan import (
    SETPOINT_CHANNELS,
    UNITS,
    LiveIdConfig,
    Plan,
    Schedule,
    load_plan,
)
from groundstation.plan.altitude import AltitudeHoldConfig
from groundstation.plan.checks import plan_warnings
from groundstation.plan.design import design_notes
from groundstation.plan.excitation import prbs_shift
from groundstation.plan.toml import TomlSource

__all__ = ["command", "plot_lines", "summarize"]

SHIFT_WARN_TICKS = 20
"""PRBS axes closer than this many ticks (2 s at 10 Hz) are flagged: correlated at short lags."""


def _excitation_text(spec: Any, rate: float) -> str:
    unit = UNITS[spec.axis]
    if spec.signal == "prbs":
        return f"{spec.axis} PRBS ±{spec.amplitude:g} {unit}"
    if spec.signal == "chirp":
        return (
            f"{spec.axis} {spec.sweep} chirp ±{spec.amplitude:g} {unit} "
            f"{spec.f_start_hz:g}-{spec.f_end_hz:g} Hz"
        )
    width = f" width {spec.width / rate:g} s" if spec.signal == "doublet" else ""
    return f"{spec.axis} {spec.signal} {spec.amplitude:g} {unit} at {spec.start / rate:g} s{width}"


def _settings(plan: Plan) -> dict[str, Any]:
    """``[altitude_hold]`` and ``[live_id]`` as the flight will use them: every value, which
    were defaulted (``defaults``), and whether each acts (``active``): a plan without an
    ``[altitude_hold]`` flies its thrust open loop; one without ``[live_id]`` identifies
    nothing unless ``fly --live-id`` asks, with the defaults."""
    given = TomlSource(text=plan.text, source=plan.source).lines  # the keys the file names
    out: dict[str, Any] = {}
    for key, config, default in (("altitude_hold", plan.altitude_hold, AltitudeHoldConfig()),
                                 ("live_id", plan.live_id, LiveIdConfig())):
        values = {k: list(v) if isinstance(v, tuple) else v
                  for k, v in vars(config or default).items()}
        out[key] = {"active": config is not None,
                    "defaults": sorted(k for k in values if (key, k) not in given)} | values
    return out


def summarize(plan: Plan, schedule: Schedule) -> dict[str, Any]:
    """Everything ``plan check`` reports, JSON-ready (times in s, thrust in PWM)."""
    rate = schedule.rate_hz
    phases, prbs, warnings = [], [], plan_warnings(plan)
    for spec, ph in zip(plan.phases, schedule.phases, strict=True):
        entry = ph.to_dict() | {"duration_s": ph.duration, "setpoints": ph.n_ticks}
        if spec.kind in ("takeoff", "landing"):
            entry["excitation"] = f"thrust {spec.thrust_start} -> {spec.thrust_end} PWM"
        elif spec.kind == "hover":
            entry["excitation"] = f"level, thrust {spec.thrust_start} PWM"
        else:
            entry["excitation"] = "; ".join(_excitation_text(e, rate) for e in spec.excitation)
        phases.append(entry)
        chains = [e for e in spec.excitation if e.signal == "prbs"]
        for e in chains:
            fig = e.prbs_figures(n_ticks=ph.n_ticks)
            fig |= {
                "phase": ph.name,
                "axis": e.axis,
                "amplitude": e.amplitude,
                "unit": UNITS[e.axis],
                "period_s": fig["period_ticks"] / rate,
                "clock_period_s": e.clock_period / rate,
            }
            prbs.append(fig)
            if fig["periods_covered"] < 1:
                warnings.append(
                    f"phase {ph.name} {e.axis}: the PRBS covers only "
                    f"{fig['periods_covered']:.2f} of its period; its persistence "
                    "of excitation holds over whole periods"
                )
        for i, a in enumerate(chains):
            for b in chains[i + 1 :]:
                if (a.register_length, a.clock_period) != (b.register_length, b.clock_period):
                    continue
                d = prbs_shift(register_length=a.register_length, seed_a=a.seed, seed_b=b.seed)
                lag = min(d, (1 << a.register_length) - 1 - d) * a.clock_period
                prbs[-len(chains) + i].setdefault("lag_ticks", {})[b.axis] = lag
                if lag < SHIFT_WARN_TICKS:
                    warnings.append(
                        f"phase {ph.name}: {a.axis} and {b.axis} PRBS are the same "
                        f"sequence only {lag} ticks apart; choose seeds further "
                        "apart so the axes are uncorrelated"
                    )
    return {
        "name": plan.name,
        "source": plan.source,
        "description": plan.description,
        "rate_hz": rate,
        "duration_s": schedule.duration,
        "n_setpoints": len(schedule),
        "hover_thrust": plan.hover_thrust,
        "vehicle": vars(plan.vehicle),
        "safety": vars(plan.safety),
        "parameters": dict(plan.parameters),
        **_settings(plan),
        "phases": phases,
        "prbs": prbs,
        "warnings": warnings,
    }


def _print_check(console: Console, s: dict[str, Any]) -> None:
    console.print(f"[bold]plan {shown_markup(s['name'])}[/] ({shown_markup(s['source'])}): "
                  "[green]valid[/]")
    console.print(
        f"{s['n_setpoints']} setpoints at {s['rate_hz']:g} Hz, duration {s['duration_s']:g} s"
    )
    table = Table(box=None, pad_edge=False, header_style="bold")
    for col, just in (
        ("#", "right"),
        ("phase", "left"),
        ("kind", "left"),
        ("start s", "right"),
        ("end s", "right"),
        ("setpoints", "right"),
        ("what", "left"),
    ):
        table.add_column(col, justify=just)  # type: ignore[arg-type]
    for p in s["phases"]:
        table.add_row(
            str(p["id"]),
            shown_markup(p["name"]),
            p["kind"],
            f"{p['start_s']:g}",
            f"{p['end_s']:g}",
            str(p["setpoints"]),
            shown_markup(p["excitation"]),
        )
    console.print(table)
    if s["prbs"]:
        prbs = Table(box=None, pad_edge=False, header_style="bold")
        for col in ("PRBS", "amplitude", "bits", "seed", "period", "clock", "PE order", "periods"):
            prbs.add_column(col, justify="left" if col == "PRBS" else "right", no_wrap=True)
        for f in s["prbs"]:
            prbs.add_row(
                f"{shown_markup(f['phase'])}/{f['axis']}",
                f"±{f['amplitude']:g} {f['unit']}",
                str(f["register_length"]),
                str(f["seed"]),
                f"{f['period_ticks']} = {f['period_s']:g} s",
                str(f["clock_period_ticks"]),
                str(f["pe_order_ticks"]),
                f"{f['periods_covered']:.2f}",
            )
        console.print(prbs)
        lags = [
            f"{f['axis']}-{k} {v}" for f in s["prbs"] for k, v in f.get("lag_ticks", {}).items()
        ]
        from groundstation.flight.blocks import BLOCK_PERIOD_S  # the flight's log rate

        per_tick = round(1.0 / (s["rate_hz"] * BLOCK_PERIOD_S))
        console.print(
            f"(period, clock and PE order in setpoint ticks of {1 / s['rate_hz']:g} s; sysid's "
            f"past and future count log samples, {per_tick} per tick at "
            f"{1 / BLOCK_PERIOD_S:g} Hz)"
            + (f"; lags between PRBS axes: {', '.join(lags)} ticks" if lags else "")
        )
    v, sf = s["vehicle"], s["safety"]
    console.print(
        f"limits: |roll| <= {v['max_roll_deg']:g} deg, |pitch| <= "
        f"{v['max_pitch_deg']:g} deg, |yaw rate| <= {v['max_yaw_rate_deg_s']:g} deg/s,"
        f" thrust {v['thrust_min']}-{v['thrust_max']} PWM, take-off at >= "
        f"{v['min_vbat']:g} V; a battery flies {v['flight_time_s']:g} s"
    )
    abort = (
        f"descend {sf['descent_duration']:g} s at <= {sf['descent_thrust']} PWM, then stop"
        if sf["on_abort"] == "descend"
        else "stop the motors"
    )
    console.print(f"on abort: {abort}")
    for line in _settings_lines(s):
        console.print(shown_markup(line), highlight=False)
    if s["parameters"]:
        console.print("firmware parameters for the flight (restored after it): " + ", ".join(
            f"{shown_markup(k)} = {v:g}" for k, v in s["parameters"].items()))
    for w in s["warnings"]:
        console.print(f"[yellow]warning:[/] {shown_markup(w)}")


def _settings_lines(s: dict[str, Any]) -> list[str]:
    """``[altitude_hold]`` and ``[live_id]`` for the text of ``plan check`` (:func:`_settings`)."""
    h, lid = s["altitude_hold"], s["live_id"]
    if h["active"]:
        hold = (f"altitude hold: {h['target_m']:g} m on {h['variable']} in "
                f"{', '.join(h['kinds'])}; kp {h['kp']:g} PWM/m, ki {h['ki']:g} PWM/(m s), "
                f"kd {h['kd']:g} PWM/(m/s), trim ±{h['max_trim']} PWM")
        if h["defaults"]:
            hold += f" (defaults: {', '.join(h['defaults'])})"
    else:
        hold = (f"altitude hold: none (no [altitude_hold] table): thrust open loop from "
                f"hover_thrust {s['hover_thrust']} PWM, no height held")
    live = (f"{', '.join(lid['inputs'])} -> {', '.join(lid['outputs'])}, order {lid['order']}, "
            f"past {lid['past']}, future {lid['future']}, every {lid['update_period']:g} s")
    if lid["active"]:
        live = "live identification ([live_id]): " + live + (
            f" (defaults: {', '.join(lid['defaults'])})" if lid["defaults"] else "")
    else:
        live = ("live identification: off (no [live_id] table); fly --live-id would use the "
                f"defaults: {live}")
    return [hold, live]


def plot_lines(values: np.ndarray, *, width: int, height: int) -> list[str]:
    """A ``height`` x ``width`` character plot of ``values`` (n,): each column spans the min to
    max of its samples (so a PRBS shows as a band, a ramp as a line); top row = max value."""
    n = len(values)
    edges = np.linspace(0, n, width + 1).astype(int)
    lo, hi = float(values.min()), float(values.max())
    scale = (height - 1) / (hi - lo) if hi > lo else 0.0
    grid = [[" "] * width for _ in range(height)]
    for c in range(width):
        chunk = values[edges[c] : max(edges[c + 1], edges[c] + 1)]
        top = round((float(chunk.max()) - lo) * scale) if scale else (height - 1) // 2
        bottom = round((float(chunk.min()) - lo) * scale) if scale else top
        for r in range(bottom, top + 1):
            grid[height - 1 - r][c] = "█"
    return ["".join(row) for row in grid]


def _print_show(console: Console, schedule: Schedule, *, width: int, height: int) -> None:
    n = len(schedule)
    width = max(10, min(width, n))
    console.print(
        f"[bold]plan {shown_markup(schedule.name)}[/]: {n} setpoints, "
        f"{schedule.duration:g} s at {schedule.rate_hz:g} Hz"
    )
    for axis in SETPOINT_CHANNELS:
        values = getattr(schedule, axis).astype(float)
        console.print(f"[bold cyan]{axis}[/] " + shown_markup(f"[{UNITS[axis]}]"))
        for r, line in enumerate(plot_lines(values, width=width, height=height)):
            label = (
                f"{values.max():g}" if r == 0 else f"{values.min():g}" if r == height - 1 else ""
            )
            console.print(f"{label:>8} │{line}", highlight=False)
    ruler = ["─"] * width
    for ph in schedule.phases:
        col = min(width - 1, ph.start_tick * width // n)
        ruler[col] = str(ph.id % 10)
    console.print(f"{'phases':>8} └{''.join(ruler)}", highlight=False)
    console.print(f"{'':>8}  0 s{f'{schedule.duration:g} s':>{width - 3}}", highlight=False)
    for ph in schedule.phases:
        console.print(f"{'':>8}  {ph.id}: {ph.start:g}-{ph.end:g} s {shown_markup(ph.name)} "
                      f"({ph.kind})")


@click.group("plan")
def command() -> None:
    """Validate and look at flight plans (flightplans/*.toml).

    \b
    Examples:
      groundstation plan check prbs-3axis
      groundstation plan show hover-check          # a shipped plan, or a path to a .toml
      groundstation plan show prbs-3axis --json > schedule.json
    """


@command.command("check", short_help="Validate a plan; print its timeline and PRBS figures.")
@click.argument("plan")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def check(plan: str, as_json: bool) -> None:
    """Validate PLAN; print its timeline, duration, setpoint count and PRBS figures.

    PLAN is a path or the name of a shipped plan (flightplans/NAME.toml).

    \b
    Example:
      groundstation plan check prbs-3axis
    """
    loaded = load_plan(plan)
    if loaded.live_id is not None:  # as fly checks it: the names, and room for one update
        from groundstation.commands.fly import check_live_plan

        check_live_plan(loaded)
    summary = summarize(loaded, loaded.compile())
    if as_json:
        click.echo(json.dumps(summary, indent=2))
    else:
        _print_check(output_console(), summary)


@command.command("show", short_help="Plot a plan's setpoints per axis, or dump them as JSON.")
@click.argument("plan")
@click.option("--json", "as_json", is_flag=True, help="Dump the whole schedule as JSON.")
@click.option(
    "--width",
    type=click.IntRange(10, 1000),
    default=None,
    help="Plot width in characters [default: the terminal's; piped: 88].",
)
@click.option(
    "--height", type=click.IntRange(3, 50), default=5, show_default=True, help="Rows per axis."
)
@click.option("--rrd", type=click.Path(path_type=Path, dir_okay=False), default=None,
              help="Write the setpoints and phases to this Rerun .rrd file instead; an "
                   "existing file needs --force.")
@click.option("--force", is_flag=True, help="Replace the --rrd file if it exists.")
def show(plan: str, as_json: bool, width: int | None, height: int, rrd: Path | None,
         force: bool) -> None:
    """Draw PLAN's setpoints per axis in the terminal, or dump them (--json).

    \b
    Example:
      groundstation plan show pitch-only --height 8
    """
    if rrd is not None:  # before any work
        check_output(rrd, option="--rrd", suffixes=(".rrd",),
                     inputs=[Path(plan)] if Path(plan).is_file() else [], overwrite=force,
                     force_flag="--force")
    loaded = load_plan(plan)
    schedule = loaded.compile()
    if rrd is not None:  # with --json too (it was ignored there)
        from groundstation.live import open_view, plot_plan  # Rerun only when asked for

        plot_plan(schedule=schedule, view=open_view(mode="save", name=schedule.name, rrd_path=rrd))
        click.echo(f"wrote {rrd}", err=as_json)  # standard output keeps the JSON alone
    if as_json:
        click.echo(json.dumps(schedule.to_dict()))
        return
    if rrd is not None:
        return
    console = output_console(width=None if width is None else width + 12)
    if width is None:  # the terminal's width, or 100 columns when piped
        width = (console.width if console.is_terminal else 100) - 12
    _print_show(console, schedule, width=width, height=height)
    header, keys = design_notes(loaded.text)
    if header or keys:
        console.print("[bold]design[/] (the plan's '# design:' notes)")
        for note in header:
            console.print(f"  {shown_markup(note)}", highlight=False)
        for key, why in keys:
            console.print(f"  {shown_markup(key)}: {shown_markup(why)}", highlight=False)


command.add_command(design)
