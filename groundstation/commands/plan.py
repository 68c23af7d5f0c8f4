"""``groundstation plan check PLAN`` and ``groundstation plan show PLAN``.

``check`` validates a plan (errors name key and line; exit 2) and prints the phase timeline, the
duration, the setpoint count, and for each PRBS its period, clock period and order of persistent
excitation; ``show`` draws the setpoints per axis in the terminal or dumps the schedule as JSON,
and prints a designed plan's notes; ``design`` writes the next flight's plan from an identified
model (:mod:`groundstation.plan.design`). PLAN is a path or the name of a shipped plan
(``flightplans/NAME.toml``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import click
import numpy as np
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from cfcommon.cli import FiniteFloat, check_output, output_console
from groundstation.errors import GroundStationError, PlanError
from groundstation.plan import SETPOINT_CHANNELS, UNITS, Plan, Schedule, load_plan, parse_plan
from groundstation.plan.aliasing import axis_shares
from groundstation.plan.design import (
    MAX_SATURATION,
    ModelFacts,
    design_notes,
    design_plan,
    saturated,
)
from groundstation.plan.excitation import prbs_shift
from groundstation.plan.toml import dotted

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


def summarize(plan: Plan, schedule: Schedule) -> dict[str, Any]:
    """Everything ``plan check`` reports, JSON-ready (times in s, thrust in PWM)."""
    rate = schedule.rate_hz
    phases, prbs, warnings = [], [], []
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
        "phases": phases,
        "prbs": prbs,
        "warnings": warnings,
    }


def _print_check(console: Console, s: dict[str, Any]) -> None:
    console.print(f"[bold]plan {escape(s['name'])}[/] ({escape(s['source'])}): [green]valid[/]")
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
            escape(p["name"]),
            p["kind"],
            f"{p['start_s']:g}",
            f"{p['end_s']:g}",
            str(p["setpoints"]),
            escape(p["excitation"]),
        )
    console.print(table)
    if s["prbs"]:
        prbs = Table(box=None, pad_edge=False, header_style="bold")
        for col in ("PRBS", "amplitude", "bits", "seed", "period", "clock", "PE order", "periods"):
            prbs.add_column(col, justify="left" if col == "PRBS" else "right", no_wrap=True)
        for f in s["prbs"]:
            prbs.add_row(
                f"{escape(f['phase'])}/{f['axis']}",
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
        console.print(
            "(period, clock and PE order in setpoint ticks)"
            + (f"; lags between PRBS axes: {', '.join(lags)} ticks" if lags else "")
        )
    v, sf = s["vehicle"], s["safety"]
    console.print(
        f"limits: |roll| <= {v['max_roll_deg']:g} deg, |pitch| <= "
        f"{v['max_pitch_deg']:g} deg, |yaw rate| <= {v['max_yaw_rate_deg_s']:g} deg/s,"
        f" thrust {v['thrust_min']}-{v['thrust_max']} PWM, take-off at >= "
        f"{v['min_vbat']:g} V"
    )
    abort = (
        f"descend {sf['descent_duration']:g} s at <= {sf['descent_thrust']} PWM, then stop"
        if sf["on_abort"] == "descend"
        else "stop the motors"
    )
    console.print(f"on abort: {abort}")
    if s["parameters"]:
        console.print("firmware parameters for the flight (restored after it): " + ", ".join(
            f"{escape(k)} = {v:g}" for k, v in s["parameters"].items()))
    for w in s["warnings"]:
        console.print(f"[yellow]warning:[/] {escape(w)}")


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
        f"[bold]plan {escape(schedule.name)}[/]: {n} setpoints, "
        f"{schedule.duration:g} s at {schedule.rate_hz:g} Hz"
    )
    for axis in SETPOINT_CHANNELS:
        values = getattr(schedule, axis).astype(float)
        console.print(f"[bold cyan]{axis}[/] " + escape(f"[{UNITS[axis]}]"))
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
        console.print(f"{'':>8}  {ph.id}: {ph.start:g}-{ph.end:g} s {escape(ph.name)} ({ph.kind})")


@click.group("plan")
def command() -> None:
    """Validate and look at flight plans (flightplans/*.toml).

    \b
    Examples:
      groundstation plan check prbs-3axis
      groundstation plan show flightplans/hover-check.toml
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
              help="Write the setpoints and phases to this Rerun .rrd file instead.")
def show(plan: str, as_json: bool, width: int | None, height: int, rrd: Path | None) -> None:
    """Draw PLAN's setpoints per axis in the terminal, or dump them (--json).

    \b
    Example:
      groundstation plan show pitch-only --height 8
    """
    if rrd is not None and not as_json:  # before any work; an existing .rrd is replaced
        check_output(rrd, option="--rrd", suffixes=(".rrd",),
                     inputs=[Path(plan)] if Path(plan).is_file() else [], overwrite=True)
    loaded = load_plan(plan)
    schedule = loaded.compile()
    if as_json:
        click.echo(json.dumps(schedule.to_dict()))
        return
    if rrd is not None:
        from groundstation.live import open_view, plot_plan  # Rerun only when asked for

        plot_plan(schedule=schedule, view=open_view(mode="save", name=schedule.name, rrd_path=rrd))
        click.echo(f"wrote {rrd}")
        return
    console = output_console(width=None if width is None else width + 12)
    if width is None:  # the terminal's width, or 100 columns when piped
        width = (console.width if console.is_terminal else 100) - 12
    _print_show(console, schedule, width=width, height=height)
    header, keys = design_notes(loaded.text)
    if header or keys:
        console.print("[bold]design[/] (the plan's '# design:' notes)")
        for note in header:
            console.print(f"  {escape(note)}", highlight=False)
        for key, why in keys:
            console.print(f"  {escape(key)}: {escape(why)}", highlight=False)


def _flown_seeds(plans: list[Plan]) -> set[tuple[int, int]]:
    return {(e.register_length, e.seed) for p in plans for ph in p.phases
            for e in ph.excitation if e.signal == "prbs"}


def _session_plan(path: Path) -> Plan:
    """The plan a session flew (its ``plan_text``), for its seeds."""
    from cfsession import open_session

    meta = open_session(path).meta
    text, name = meta.get("plan_text"), meta.get("plan_name")
    if not isinstance(text, str) or not text.strip():
        raise PlanError(f"{path}: the session holds no plan text; pass sessions recorded by "
                        "`groundstation fly`")
    return parse_plan(text=text, source=f"{path} (plan flown)",
                      name=name if isinstance(name, str) and name else "flown")


def _measured(model: Any, sessions: tuple[Path, ...]
              ) -> tuple[dict[str, float], str, float, dict[str, float]]:
    """On ``sessions``: the mean fit per output, simulation over 2 s windows (initial state
    estimated per window; longer for many states on few outputs:
    :func:`sysid.validate.simulation_window`) and 1-step prediction, as ``sysid compare``
    reports them, the share of samples with an input at its limit
    (:func:`groundstation.plan.design.saturated`) and the top-band share of each axis' motor
    combination (:func:`groundstation.plan.aliasing.axis_shares`)."""
    from sysid import compare, detrend_data
    from sysid.errors import SysIdError
    from sysid.session_io import load_experiments
    from sysid.validate import simulation_window

    window, one, at, inputs, lengths = [], [], [], [], set()
    for path in sessions:
        try:
            raw = load_experiments(path, inputs=model.input_names, outputs=model.output_names,
                                   window="auto", dt=model.dt, detrend=None)
            at += [saturated(d.u) for d in raw]
            inputs += [d.u for d in raw]
            data = [detrend_data(d)[0] for d in raw]
            win = simulation_window(dt=model.dt, n_samples=min(d.n_samples for d in data),
                                    n_states=model.n_states, n_outputs=model.n_outputs)
            lengths.add(f"{win:g}")
            window.append(np.ravel(compare(model, data, window=win, warn=False).fit))
            one.append(np.ravel(compare(model, data, horizon=1, warn=False).fit))
        except SysIdError as exc:
            raise GroundStationError(f"{path}: cannot validate the model on it: "
                                     f"{str(exc).splitlines()[0]}") from None
    names = model.output_names
    w, h = np.mean(window, axis=0), np.mean(one, axis=0)
    shown = ", ".join(f"{n} {a:.1f}/{b:.1f}" for n, a, b in zip(names, w, h, strict=True)
                      if n.startswith("gyro") or len(names) <= 3)
    return ({n: float(f) for n, f in zip(names, w, strict=True)},
            f"{'/'.join(sorted(lengths))} s windows on {len(sessions)} flown session(s); "
            f"window/1-step: {shown}",
            float(np.concatenate(at).mean()),
            axis_shares(inputs, input_names=model.input_names))


def _flown_firmware(sessions: tuple[Path, ...]) -> dict[str, float]:
    """The firmware parameters the sessions were flown with (``group.name``: value): those
    recorded at connect, with the plan's ``[parameters]`` set for the flight over them; the
    last session's value where they differ."""
    from cfsession import open_session
    from groundstation.commands.info import finite_number, flown_parameters

    out: dict[str, float] = {}
    for path in sessions:
        session = open_session(path)
        params = session.json_meta("params")
        for group, values in (params.items() if isinstance(params, dict) else ()):
            for name, value in (values.items() if isinstance(values, dict) else ()):
                if finite_number(value):
                    out[f"{group}.{name}"] = float(value)
        out |= {name: float(v["value"]) for name, v in flown_parameters(session).items()}
    return out


@command.command("design", short_help="Design the next flight's excitation from a model.")
@click.option("--model", "model_path", required=True,
              type=click.Path(path_type=Path, dir_okay=False),
              help="Identified model (.h5, .json or .mat from `sysid identify --out`).")
@click.option("--from", "from_plan", default="prbs-3axis", show_default=True,
              help="Plan to start from: its limits, phases and comments are kept.")
@click.option("--out", required=True, type=click.Path(path_type=Path, dir_okay=False),
              help="The new plan (.toml); its file name is the plan's name.")
@click.option("--flown", multiple=True, type=click.Path(path_type=Path, dir_okay=False),
              help="A session already flown (repeat): its seeds are avoided and the model's "
                   "fits on it say which axes to excite more.")
@click.option("--max-saturation", type=FiniteFloat(min=0, max=100),
              default=100 * MAX_SATURATION, show_default=True,
              help="Percent of the flown excitation with a model input (motor) at its limit "
                   "above which no amplitude is raised: more would only be clipped.")
@click.option("--force", is_flag=True, help="Replace --out if it exists.")
def design(model_path: Path, from_plan: str, out: Path, flown: tuple[Path, ...],
           max_saturation: float, force: bool) -> None:
    """Write the next flight's plan: PRBS clock and register from the model's modes (the
    chip made longer than flown only by a model that explains every axis to 90 %),
    amplitudes raised on the axes the model explains poorly (within the plan's limits, and
    only while the flown motors kept clear of their limits), seeds unlike those flown. Each
    changed value carries a '# design:' comment saying why, and
    `groundstation plan show NEW.toml` prints them (rules: docs/flightplans.md).

    \b
    Examples:
      groundstation plan design --model model.h5 --out next.toml
      groundstation plan design --model model.h5 --from prbs-3axis \\
        --flown sessions/prbs-3axis-A.h5 --flown sessions/prbs-3axis-B.h5 --out next.toml
    """
    source = [Path(from_plan)] if Path(from_plan).is_file() else []
    check_output(out, option="--out", suffixes=(".toml",), inputs=[model_path, *source, *flown],
                 overwrite=force, force_flag="--force")
    base = load_plan(from_plan)
    flown_plans = [_session_plan(p) for p in flown]
    from sysid.errors import SysIdError
    from sysid.model_io import load  # the hardened loader of untrusted model files

    try:
        model = load(model_path)
    except SysIdError as exc:
        raise GroundStationError(str(exc).splitlines()[0]) from None
    fits, fit_source, share, aliasing = (_measured(model, flown) if flown
                                         else (None, "", None, None))
    facts = ModelFacts.from_model(model, source=model_path.name, fits=fits,
                                  fit_source=fit_source)
    result = design_plan(base, facts, name=out.stem, flown=_flown_seeds([base, *flown_plans]),
                         saturation=share, max_saturation=max_saturation / 100,
                         aliasing=aliasing, firmware=_flown_firmware(flown), source=str(out))
    out.write_text(result.plan.text, encoding="utf-8")
    console = output_console()
    for note in result.notes:
        console.print(escape(note), highlight=False)
    for ch in result.changes:
        console.print(f"  {escape(dotted(ch.path))} = {ch.value}: "
                      f"{escape(ch.why)}", highlight=False)
    console.print(f"wrote {out}; check it with `groundstation plan check {out}`")
