"""``groundstation demo``: the README's main command (fly, record, identify)."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import click

from groundstation.commands.info import describe
from groundstation.session import SessionWriter, open_session, standard_streams
from groundstation.session_schema import log_block_spec

__all__ = ["command"]


@click.command("demo")
@click.option(
    "--out",
    type=click.Path(path_type=Path),
    default=None,
    help="Folder for the session files (default: a new temporary folder).",
)
def command(out: Path | None) -> None:
    """Run the end-to-end demo.

    Until the simulated flight lands, it writes a synthetic session (three 50 Hz log blocks,
    setpoints, phases, events) and reads it back.
    """
    folder = out or Path(tempfile.mkdtemp(prefix="cf-demo-"))
    path = folder / "synthetic.h5"
    blocks = [
        log_block_spec(
            name="motors",
            variables=[(f"motor.m{i}", "uint16_t") for i in range(1, 5)],
            period_s=0.02,
        ),
        log_block_spec(name="acc", variables=[(f"acc.{a}", "float") for a in "xyz"], period_s=0.02),
        log_block_spec(
            name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"], period_s=0.02
        ),
    ]
    with SessionWriter(
        path,
        streams=[*blocks, *standard_streams()],
        metadata={"uri": "synthetic://", "plan_name": "synthetic"},
    ) as w:
        w.phase(t=0.0, phase_id=0, name="hover", kind="hover")
        for k in range(500):
            t = k * 0.02
            w.append("motors", (t, 1000 + 20 * k, *(30000 + int(1000 * math.sin(t)),) * 4))
            w.append("acc", (t, 1000 + 20 * k, 0.0, 0.0, 1.0))
            w.append("gyro", (t, 1000 + 20 * k, math.sin(t), math.cos(t), 0.0))
            if k % 5 == 0:
                w.append("setpoints", (t, 0.0, 0.0, 0.0, 30000, 0, k // 5))
        w.event(t=10.0, text="synthetic session complete")
    d = describe(open_session(path))
    click.echo(
        f"wrote and read back {path}: {d['duration_s']:.2f} s, "
        + ", ".join(f"{k} {v['rows']} rows" for k, v in d["streams"].items())
    )
