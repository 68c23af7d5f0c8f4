"""``groundstation plan design``: the next flight's plan from an identified model.

The model file is read with the hardened loader of ``sysid`` and its numbers handed to
:func:`groundstation.plan.design.design_plan` (:class:`~groundstation.plan.design.ModelFacts`);
sessions already flown (``--flown``) add what the model cannot say by itself: their seeds (to be
avoided), the model's fits on them (which axes to excite more), the share of samples with a motor
at its limit, the top-band share of each axis' motor combination and the firmware parameters
they were flown with. ``sysid`` is imported inside the functions only (flying loads none).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import click
import numpy as np

from cfcommon.cli import (
    FiniteFloat,
    check_output,
    output_console,
    shown_markup,
    shown_text,
    whole_file,
)
from groundstation.errors import GroundStationError, PlanError
from groundstation.plan import Plan, load_plan, parse_plan
from groundstation.plan.aliasing import axis_shares
from groundstation.plan.design import MAX_SATURATION, ModelFacts, design_plan, saturated
from groundstation.plan.toml import dotted

__all__ = ["design"]


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
                                   window="auto", dt=model.dt, detrend=None,
                                   verb="validate the model on")
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


@click.command("design", short_help="Design the next flight's excitation from a model.")
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
    for path, other in zip(flown, flown_plans, strict=True):
        if other.name != base.name:  # its seeds are still avoided: a warning, not a refusal
            click.echo(shown_text(
                f"warning: {path} flew plan '{other.name}', not '{base.name}' (--from): the "
                "fits, motor-limit and motor-log checks measure that experiment, not this "
                f"plan's; pass sessions flown with '{base.name}', or design --from the plan "
                "they flew"), err=True)
    from sysid.errors import SysIdError
    from sysid.model_io import load  # the hardened loader of untrusted model files

    try:
        model = load(model_path)
    except SysIdError as exc:
        raise GroundStationError(str(exc)) from None  # one line; a name in it is escaped
    fits, fit_source, share, aliasing = (_measured(model, flown) if flown
                                         else (None, "", None, None))
    facts = ModelFacts.from_model(model, source=model_path.name, fits=fits,
                                  fit_source=fit_source)
    result = design_plan(base, facts, name=out.stem, flown=_flown_seeds([base, *flown_plans]),
                         saturation=share, max_saturation=max_saturation / 100,
                         aliasing=aliasing, firmware=_flown_firmware(flown), source=str(out))
    with whole_file(out) as part:  # its missing folder made, as every output's
        part.write_text(result.plan.text, encoding="utf-8")
    console = output_console()
    for note in result.notes:
        console.print(shown_markup(note), highlight=False)
    for ch in result.changes:
        console.print(f"  {shown_markup(dotted(ch.path))} = {ch.value}: "
                      f"{shown_markup(ch.why)}", highlight=False)
    console.print(f"wrote {out}; check it with `groundstation plan check {out}`")
