"""``groundstation demo``: the README's main command: fly, record, identify, validate.

Flies the thesis' ``prbs-3axis`` plan and a second realisation of it (every PRBS advanced in its
m-sequence, see :func:`groundstation.plan.variants.advance_prbs`) on two simulated Crazyflies
through the real cflib stack, records both sessions, identifies a model with IEM from the first
flight's excitation phase (past, future and order chosen by validation on the last 30 % of that
phase, :mod:`sysid.auto`, unless given), and validates it on the second flight the way a quadrotor
model must be validated: simulation over short windows (initial state estimated per window) and
k-step-ahead prediction through the innovation form (see ``docs/sysid.md``).
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import click
import numpy as np
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

from cfcommon.cli import FiniteFloat, output_console, output_table
from groundstation.commands.fly import PlainProgress
from groundstation.errors import GroundStationError
from groundstation.flight import FlightResult, fly_plan
from groundstation.plan import Plan, load_plan
from groundstation.plan.variants import advance_prbs
from groundstation.recorder import check_folder

__all__ = ["RESULTS", "command"]

RESULTS = ("iem-model.h5", "demo-summary.json")
"""The files a demo writes besides its two sessions."""


def _fly(plan: Plan, *, uri: str, out: Path, label: str, console: Console) -> FlightResult:
    """Fly with a progress bar driven by the runner's tick hook (runs in the runner's thread);
    not on a terminal, ``fly``'s plain ``[fly]`` lines on stderr instead."""
    if not console.is_terminal:
        click.echo(f"{label}: {uri}", err=True)
        result = fly_plan(plan=plan, out=out, uri=uri,
                          listeners=[PlainProgress(duration_s=plan.duration,
                                                   every_s=max(5.0, plan.duration / 10))])
        result.raise_if_aborted()
        return result
    n = plan.n_setpoints
    columns = (TextColumn(f"[bold]{label}[/]"), BarColumn(), TextColumn("{task.description}"),
               TimeRemainingColumn())
    with Progress(*columns, console=console, transient=False) as progress:
        task = progress.add_task("", total=n)
        schedule = plan.compile()

        def tick(k: int) -> None:
            phase = schedule.phases[int(schedule.phase_id[k])].name
            progress.update(task, completed=k + 1, description=f"{phase:>10s}  {k + 1}/{n}")

        result = fly_plan(plan=plan, out=out, uri=uri, tick_hook=tick)
    result.raise_if_aborted()
    return result


def _check_out(folder: Path, *, force: bool) -> None:
    """The recorder's rule for ``folder``; a former demo's model and summary are replaced only
    with ``force`` (the sessions are new files: named by their start time)."""
    check_folder(folder)  # created if missing, must be writable
    former = [name for name in RESULTS if (folder / name).exists()]
    if former and not force:
        raise click.BadParameter(f"{folder} already holds a demo's results ({', '.join(former)}"
                                 "); pass --force to replace them or choose another folder",
                                 param_hint="--out")


class _Speed(FiniteFloat):
    """A speed factor, or ``inf``: flat out, in lock-step with the ground station."""

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> float:
        if isinstance(value, str) and value.strip().lower() == "inf":
            return float("inf")
        return super().convert(value, param, ctx)

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        return f"{super().get_metavar(param, ctx)}|inf"


@click.command("demo")
@click.option("--out", type=click.Path(path_type=Path), default=None,
              help="Folder for the session and model files (default: a new temporary folder).")
@click.option("--speed", type=_Speed(min=1, max=100), default=10.0, show_default=True,
              help="Simulation speed factor (the 112 s plan takes 112/speed s); inf: flat out, "
                   "in lock-step with the ground station, so every run records the same "
                   "flights and chooses the same model.")
@click.option("--order", type=click.IntRange(1, 40), default=None,
              help="Model order (default: chosen by validation; the thesis used 8).")
@click.option("--past", type=click.IntRange(1, 500), default=None,
              help="Past horizon, samples (default: chosen by validation; the thesis used 60).")
@click.option("--future", type=click.IntRange(2, 200), default=None,
              help="Future horizon, samples (default: chosen by validation; the thesis used 17).")
@click.option("--advance", type=click.IntRange(1, 1_000_000), default=500, show_default=True,
              help="Chips the validation flight's PRBS is advanced in its m-sequence.")
@click.option("--force", is_flag=True,
              help="Replace a former demo's model and summary in --out.")
def command(out: Path | None, speed: float, order: int | None, past: int | None,
            future: int | None, advance: int, force: bool) -> None:
    """Fly two PRBS flights on the simulator, identify a model from one, validate on the other.

    \b
    The whole loop of the thesis, with the real cflib stack against the simulated Crazyflie:
      1. fly prbs-3axis (roll/pitch ±25 deg, yaw rate ±50 deg/s) on sim://0
      2. fly it again with the PRBS advanced by --advance chips on sim://1
      3. identify with IEM from flight 1's excitation phase; past, future and order are
         chosen by validation on its last 30 % (--order 8 --past 60 --future 17: the thesis),
         motors -> acc.x, acc.y, acc.z and gyro as in the thesis (sysid identify's defaults
         are acc.z and gyro, and it tries PARSIM-K too: its model can differ)
      4. print the poles and the fits on flight 2: windowed simulation (2 s, as sysid compare by
         default) and k-step prediction

    \b
    Examples (then a session by the name the demo printed: each run records new ones):
      groundstation demo --out demo-out --speed 20
      groundstation info demo-out/prbs-3axis-20261122T100000Z.h5
      groundstation replay demo-out/prbs-3axis-20261122T100000Z.h5 --rrd flight.rrd
    """
    from sysid import compare
    from sysid.cli_support import poles_rich_table
    from sysid.cli_sweep import choose
    from sysid.errors import SysIdError, first_line
    from sysid.methods import get_method
    from sysid.session_io import load_session
    from sysid.validate import default_window

    folder = out or Path(tempfile.mkdtemp(prefix="cf-demo-"))
    _check_out(folder, force=force)
    console = output_console()  # piped (CI logs): plain tables, never wrapped
    base = load_plan("prbs-3axis")
    flights = [
        (base, f"sim://0?speed={speed:g}&seed=1", "flight 1 (identification)"),
        (advance_prbs(base, chips=advance), f"sim://1?speed={speed:g}&seed=2",
         "flight 2 (validation)"),
    ]
    paths = []
    for plan, uri, label in flights:
        result = _fly(plan, uri=uri, out=folder, label=label, console=console)
        s = result.summary
        console.print(f"  recorded {result.path} ({s.get('duration_s', float('nan')):.1f} s)")
        paths.append(result.path)

    t0 = time.perf_counter()
    ident = load_session(paths[0], window="excitation")
    iem = get_method("iem")
    given = {k: [v] for k, v in (("pasts", past), ("futures", future), ("orders", order))
             if v is not None}
    try:  # progress on stderr: a bar on a terminal, plain lines otherwise
        chosen = choose([[ident]], method=iem, options=iem.options(), grid=given,
                        label="identifying with IEM (choosing past, future and order)")
    except KeyboardInterrupt:
        click.echo(f"error: interrupted (Ctrl-C) while identifying; the sessions are kept: "
                   f"{paths[0]} {paths[1]}", err=True)
        sys.exit(130)
    except SysIdError as exc:  # fixed horizons the flight cannot support: the flights stay
        raise GroundStationError(f"identification failed: {first_line(exc)}; the sessions "
                                 f"are kept: {paths[0]} {paths[1]}") from None
    model = chosen.model
    order, past, future = chosen.best.order, chosen.best.past, chosen.best.future
    seconds = time.perf_counter() - t0
    console.print(f"chosen: {chosen.rule}")
    for w in chosen.warnings:
        console.print(f"[yellow]warning: {w}[/]")
    console.print(f"IEM: order {order}, past {past}, future {future}, "
                  f"{ident.n_samples} samples ({ident.n_samples * ident.dt:.1f} s of flight), "
                  f"identified in {seconds:.2f} s; stable: {model.is_stable}, "
                  f"predictor stable: {model.predictor_is_stable}")
    console.print(poles_rich_table(model, title="IEM model poles", console=console))
    model_path = folder / "iem-model.h5"
    model.save(model_path)

    val = load_session(paths[1], window="excitation")
    names = list(val.output_names)
    table = output_table("validation on flight 2", *names, console=console,
                         title="fit % (NRMSE, MATLAB compare)")
    window = default_window(model, n_samples=val.n_samples)  # as sysid compare's default
    simulated = (f"simulation, {window:g} s windows" if window is not None
                 else "simulation (the whole flight)")
    with console.status("validating on flight 2 ..."):
        rows = [(simulated, compare(model, val, window=window)),
                ("1-step prediction", compare(model, val, horizon=1)),
                ("10-step prediction (0.2 s)", compare(model, val, horizon=10))]
    for label, result in rows:
        table.add_row(label, *(f"{f:.1f}" for f in np.ravel(result.fit)))
    console.print(table)
    if not model.is_stable:
        console.print(f"note: largest |pole| {np.abs(model.poles()).max():.3f}. The open-loop "
                      "plant is marginally stable (body rates integrate the motor torques, tilt "
                      "integrates the rates), so estimated poles sit at |z| ~ 1 and may land just "
                      "outside; this is why a quadrotor model is validated over short windows "
                      "and by k-step prediction, not by simulating a whole flight.")
    console.print("note: acc.x/acc.y are body-frame specific force (rotor drag at these "
                  "tilts); the thesis (section 5.2.1) found them predicted poorly on its "
                  "vehicle while the rates were captured. Each window's initial state is "
                  "fitted with every channel weighted by its spread, so no channel's units "
                  "decide it.")
    summary = {
        "sessions": [str(p) for p in paths], "model": str(model_path),
        "order": order, "past": past, "future": future, "samples": ident.n_samples,
        "identify_s": seconds, "stable": bool(model.is_stable),
        "predictor_stable": bool(model.predictor_is_stable),
        "poles": [[float(z.real), float(z.imag)] for z in model.poles()],
        "outputs": names,
        "fits": {label: [float(f) for f in np.ravel(r.fit)] for label, r in rows},
    }
    (folder / "demo-summary.json").write_text(json.dumps(summary, indent=2))
    console.print(f"sessions: {paths[0]}\n          {paths[1]}\nmodel:    {model_path}")
    console.print(f"next: groundstation replay {paths[0]} --rrd flight.rrd; "
                  f"sysid compare {model_path} {paths[1]} --horizon 1")
