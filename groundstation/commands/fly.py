"""``groundstation fly PLAN``: fly a flight plan, record the session, print the summary.

Progress (phase, flight time, packets) is shown with ``rich`` on a terminal and not otherwise.
An aborted flight prints its cause and the session path on one line and exits 2.
"""

from __future__ import annotations

import importlib
import json
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import click

from groundstation.errors import GroundStationError
from groundstation.flight import FlightListener, RateLimits, fly_plan
from groundstation.link import DEFAULT_URI, check_uri
from groundstation.plans import load_plan
from groundstation.recorder import check_folder
from groundstation.session_schema import StreamSpec
from sysid.cli_types import FiniteFloat

__all__ = ["ProgressListener", "command", "open_view", "summary_lines"]


def open_view(*, mode: str, name: str) -> FlightListener:
    """The live view's listener (``groundstation.live.open_view``), imported only when asked."""
    try:
        live = importlib.import_module("groundstation.live")
    except ImportError:
        raise GroundStationError(f"--view {mode} needs groundstation.live, which this "
                                 "installation lacks; use --view none") from None
    return live.open_view(mode=mode, name=name)


class ProgressListener:
    """A ``rich`` progress bar: phase, flight time of the plan's duration, log packets."""

    def __init__(self, *, duration_s: float) -> None:
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self._progress = Progress(TextColumn("{task.description:<12}"), BarColumn(),
                                  TextColumn("{task.completed:6.1f}/{task.total:.1f} s"),
                                  TextColumn("{task.fields[packets]}"), TimeElapsedColumn(),
                                  transient=True)
        self._task = self._progress.add_task("connected", total=duration_s, packets="")
        self._t0: float | None = None
        self._packets: dict[str, int] = {}
        self._logs: set[str] = set()
        self._last = 0.0

    def begin(self, *, streams: Sequence[StreamSpec], metadata: Mapping[str, Any]) -> None:
        self._logs = {s.name for s in streams if s.kind == "log"}
        self._progress.start()

    def rows(self, stream: str, rows: Sequence[tuple]) -> None:
        update: dict[str, Any] = {}
        if stream in self._logs:
            self._packets[stream] = self._packets.get(stream, 0) + len(rows)
        elif stream == "phases":
            update["description"] = rows[-1][2].decode(errors="replace")
        elif stream == "setpoints":
            ticks = [r for r in rows if r[6] >= 0]
            if ticks and self._t0 is None:
                self._t0 = ticks[0][0]
            if self._t0 is not None:
                update["completed"] = rows[-1][0] - self._t0
        now = time.monotonic()
        if update or now - self._last > 0.2:
            self._last = now
            update["packets"] = " ".join(f"{k} {v}" for k, v in self._packets.items())
            self._progress.update(self._task, **update)

    def end(self, *, summary: Mapping[str, Any]) -> None:
        self._progress.stop()


def summary_lines(summary: Mapping[str, Any]) -> list[str]:
    """The end-of-flight summary as text lines."""
    sp = summary.get("setpoints", {})
    jit = sp.get("jitter_ms", {})
    lines = [f"flight {summary.get('plan')} on {summary.get('uri')}: "
             f"{summary.get('duration_s', 0):.1f} s"]
    for name, b in summary.get("blocks", {}).items():
        share = 100.0 * b["received"] / b["expected"] if b["expected"] else 0.0
        lines.append(f"  {name:<8} {b['received']:6d} / {b['expected']:6d} packets "
                     f"({share:.1f} %), {b['dropped']} dropped")
    extra = sp.get("sent", 0) - sp.get("scheduled", 0)
    lines.append(f"  setpoints {sp.get('scheduled', 0)} of {sp.get('planned', 0)} planned sent "
                 f"(+{extra} unlock/abort); period jitter p50 {jit.get('p50', 0):.1f} ms, "
                 f"p99 {jit.get('p99', 0):.1f} ms, max {jit.get('max', 0):.1f} ms "
                 "on the flight clock")
    lines.append(f"  file {summary.get('file')}")
    return lines


@click.command("fly")
@click.argument("plan")
@click.option("--uri", default=DEFAULT_URI, show_default=True,
              help="Crazyflie link: radio://..., usb://0, udp://127.0.0.1:19850, sim://0?speed=20.")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("sessions"),
              show_default=True, help="Folder for the session file.")
@click.option("--view", type=click.Choice(["none", "rerun", "serve"]), default="none",
              show_default=True, help="Live view: Rerun viewer, web viewer, or none.")
@click.option("--max-rate", type=FiniteFloat(min=1.0), default=None,
              help="Abort when a gyro axis exceeds this, deg/s [default: the plan's "
                   "safety.max_rate_deg_s, else 1000].")
@click.option("--timeout", "timeout_s", type=FiniteFloat(min=0.5), default=10.0,
              show_default=True, help="Seconds to wait for the connection.")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
def command(plan: str, uri: str, out: Path, view: str, max_rate: float | None, timeout_s: float,
            as_json: bool) -> None:
    """Fly a flight plan and record it to a session file.

    Connects, checks the log TOC and the battery, streams the plan's setpoints at its rate and
    lands. Ctrl-C, link loss or a limit stop the motors (after the plan's descent where it asks
    for one). PLAN is a path or a shipped plan's name.

    \b
    Examples:
      groundstation fly hover-check
      groundstation fly prbs-3axis --uri sim://0?speed=20 --out sessions --view rerun
    """
    loaded = load_plan(plan)
    check_uri(uri)  # before any viewer opens; fly_plan checks the file name before connecting
    check_folder(out)
    listeners: list[FlightListener] = []
    if view != "none":
        listeners.append(open_view(mode=view, name=loaded.name))
    if sys.stdout.isatty() and not as_json:
        listeners.append(ProgressListener(duration_s=loaded.duration))
    result = fly_plan(plan=loaded, out=out, uri=uri, listeners=listeners,
                      limits=None if max_rate is None else RateLimits(max_rate_deg_s=max_rate),
                      connect_timeout_s=timeout_s)
    if as_json:
        click.echo(json.dumps(result.summary, indent=2))
    else:
        click.echo("\n".join(summary_lines(result.summary)))
    if view == "serve" and sys.stdin.isatty():
        _keep_serving(listeners[0])
    result.raise_if_aborted()


def _keep_serving(view: FlightListener) -> None:
    """The web viewer lives in this process: keep it up after landing until Ctrl-C."""
    url = getattr(view, "url", None) or "the web viewer"
    click.echo(f"serving the flight at {url}; Ctrl-C to quit", err=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        click.echo("", err=True)
