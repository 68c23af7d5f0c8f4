"""``groundstation fly PLAN``: fly a flight plan, record the session, print the summary.

Progress (phase, flight time, packets) is a ``rich`` bar on a terminal and, otherwise (``nohup``,
CI logs), a plain line every :data:`PLAIN_EVERY_S` seconds of flight time and at each phase
start. An aborted flight prints its cause and the session path on one line and exits 2 (a
flight a listener's ``SystemExit`` ended too, whatever its code: :func:`_listener_exit`); so
does a session that could not be saved (``file_error`` in the summary: a disk that filled, a
folder deleted while flying that could not be made again). A folder moved while flying moves
the file: the summary names it where it is now, and the writer warns.
A validation flight is the plan with a different PRBS realisation (``--advance``/``--seed``, see
:mod:`groundstation.plan.variants`), named with ``--name`` (file name and ``tag`` metadata).
``--live-id`` (or a plan's ``[live_id]`` table) identifies a model while the excitation flies
(:mod:`groundstation.flight.liveid`, ``docs/live-id.md``); ``--until-converged`` ends the
excitation once its poles have settled. Only then is ``sysid`` imported.
"""

from __future__ import annotations

import contextlib
import importlib
import json
import math
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import click

from cfcommon.cli import (
    NO_ROOM,
    FiniteFloat,
    drop_failing_stdout,
    output_gone,
    shown_markup,
    shown_text,
)
from cfsession.schema import StreamSpec
from groundstation.commands.plan import summarize
from groundstation.errors import GroundStationError, PlanError
from groundstation.flight import FlightListener, FlightResult, RateLimits, fly_plan
from groundstation.flight.link import DEFAULT_URI, check_uri
from groundstation.flight.liveid import (
    Convergence,
    Engine,
    LiveIdListener,
    check_live_id,
    planned_streams,
)
from groundstation.flight.liveid_data import live_id_error
from groundstation.plan import MAX_RATE_RANGE_DEG_S, LiveIdConfig, Plan, load_plan
from groundstation.plan.toml import TomlSource
from groundstation.plan.variants import advance_prbs, reseed_prbs
from groundstation.recorder import check_folder, check_tag

__all__ = ["PlainProgress", "ProgressListener", "check_live_plan", "command", "live_id_engine",
           "live_id_listener", "open_view", "summary_lines"]


PLAIN_EVERY_S = 5.0
"""Seconds of flight time between two plain progress lines (not on a terminal)."""


def open_view(*, mode: str, name: str, web_port: int) -> FlightListener:
    """The live view's listener (``groundstation.live.open_view``), imported only when asked."""
    try:
        live = importlib.import_module("groundstation.live")
    except ImportError:
        raise GroundStationError(f"--view {mode} needs groundstation.live, which this "
                                 "installation lacks; use --view none") from None
    return live.open_view(mode=mode, name=name, web_port=web_port)


def live_id_engine() -> Engine:
    """sysid's live identification for the listener, imported only when asked for."""
    try:
        from sysid import model_io, preprocess
        from sysid.live import LiveIdentifierProcess
    except ImportError as exc:
        raise GroundStationError(f"live identification needs the sysid package ({exc}); "
                                 "install it, or fly without --live-id / [live_id]") from None
    return Engine(identifier=LiveIdentifierProcess, zoh=preprocess.zoh_resample,
                  save_model=model_io.save)


def check_live_plan(plan: Plan) -> LiveIdConfig:
    """``plan``'s live identification (its ``[live_id]`` or the defaults) checked before
    anything connects: names against the flight's log blocks
    (:func:`~groundstation.flight.liveid.check_live_id`), and an excitation long enough for
    the first update (a flight that could make none flew without saying why). One-line
    :class:`~groundstation.errors.PlanError` otherwise; ``plan check`` runs it too."""
    from sysid.factor import min_samples  # the engine's own count: sysid loads only here

    config = plan.live_id or LiveIdConfig()
    # the plan's [live_id] table: errors name its key and line; else the defaults, no line
    source = None if plan.live_id is None else TomlSource(text=plan.text, source=plan.source)
    ins, outs, dt = check_live_id(config, streams=planned_streams(plan), source=source)
    spans = [(p.start, p.start + p.duration) for p in plan.compile().phases
             if p.kind == "excitation"]
    if not spans:
        raise PlanError(f"live_id: plan {plan.name!r} has no excitation phase to identify "
                        "from; fly a plan with one, or without --live-id")
    span = spans[-1][1] - spans[0][0]
    have = int(span / dt + 1e-9)
    need = min_samples(past=config.past, future=config.future, n_channels=len(ins) + len(outs))
    if have < need:
        message = (
            f"past {config.past} + future {config.future} with {len(ins) + len(outs)} "
            f"channels need {need} samples ({need * dt:.1f} s) of excitation for the first "
            f"update; the plan excites for {span:.1f} s ({have} samples at {1 / dt:g} Hz): "
            "lower past or future in [live_id], or lengthen the excitation")
        raise live_id_error(source, "past", message)
    return config


def live_id_listener(plan: Plan, *, convergence: Convergence | None = None) -> LiveIdListener:
    """The live identification listener for ``plan`` (its ``[live_id]`` or the defaults),
    checked by :func:`check_live_plan`: a one-line error before anything connects."""
    config = check_live_plan(plan)
    return LiveIdListener(config=config, engine=live_id_engine(), convergence=convergence)


class PlainProgress:
    """Progress as plain lines on stderr: at each phase start and every ``every_s`` seconds
    of flight time, ``[fly] t 12.0/112.0 s  phase excitation  packets motors 600 ...``, and
    the live identification's ``status`` when there is one."""

    def __init__(self, *, duration_s: float, every_s: float = PLAIN_EVERY_S,
                 status: Callable[[], str] | None = None) -> None:
        self.duration_s, self.every_s, self.status = duration_s, every_s, status
        self._t0: float | None = None
        self._next = 0.0
        self._phase = "connected"
        self._packets: dict[str, int] = {}
        self._logs: set[str] = set()
        self.lines: list[str] = []

    def begin(self, *, streams: Sequence[StreamSpec], metadata: Mapping[str, Any]) -> None:
        self._logs = {s.name for s in streams if s.kind == "log"}
        self._emit(0.0)

    def rows(self, stream: str, rows: Sequence[tuple]) -> None:
        if stream in self._logs:
            self._packets[stream] = self._packets.get(stream, 0) + len(rows)
        elif stream == "phases" and rows:
            self._phase = shown_text(rows[-1][2].decode(errors="replace"))  # the plan's text
            self._emit(self._elapsed(rows[-1][0]))
        elif stream == "setpoints" and rows:
            t = self._elapsed(rows[-1][0])
            if t >= self._next:
                self._emit(t)

    def end(self, *, summary: Mapping[str, Any]) -> None:
        self._phase = "ended"
        self._emit(float(summary.get("duration_s", 0.0) or 0.0))

    def _elapsed(self, host_time: float) -> float:
        if self._t0 is None:
            self._t0 = host_time
        return host_time - self._t0

    def _emit(self, t: float) -> None:
        self._next = (t // self.every_s + 1) * self.every_s
        packets = " ".join(f"{k} {v}" for k, v in self._packets.items()) or "-"
        line = (f"[fly] t {max(t, 0.0):6.1f}/{self.duration_s:.1f} s  phase {self._phase:<12} "
                f"packets {packets}{f'  | {self.status()}' if self.status else ''}")
        self.lines.append(line)
        click.echo(line, err=True)


class ProgressListener:
    """A ``rich`` progress bar: phase, flight time of the plan's duration, log packets (and
    the live identification's ``status`` when there is one)."""

    def __init__(self, *, duration_s: float, status: Callable[[], str] | None = None) -> None:
        from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

        self._status = status
        self._progress = Progress(TextColumn("{task.description:<12}"), BarColumn(),
                                  TextColumn("{task.completed:6.1f}/{task.total:.1f} s"),
                                  TextColumn("{task.fields[packets]}"), TimeElapsedColumn(),
                                  TextColumn("{task.fields[live]}"), transient=True)
        self._task = self._progress.add_task("connected", total=duration_s, packets="",
                                             live="")
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
            update["description"] = shown_markup(rows[-1][2].decode(errors="replace"))
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
            if self._status is not None:
                update["live"] = self._status()
            self._progress.update(self._task, **update)

    def end(self, *, summary: Mapping[str, Any]) -> None:
        self._progress.stop()


def summary_lines(summary: Mapping[str, Any]) -> list[str]:
    """The end-of-flight summary as text lines."""
    sp = summary.get("setpoints", {})
    jit = sp.get("jitter_ms", {})
    lines = [f"flight {summary.get('plan')} on {summary.get('uri')}: "
             f"{summary.get('duration_s', 0):.1f} s"]
    if summary.get("aborted"):  # first: the stdout record of a flight must not read as a success
        lines.append(f"  ABORTED: {summary.get('cause') or 'cause not recorded'}")
    for name, b in summary.get("blocks", {}).items():
        share = 100.0 * b["received"] / b["expected"] if b["expected"] else 0.0
        lines.append(f"  {name:<8} {b['received']:6d} / {b['expected']:6d} packets "
                     f"({share:.1f} %), {b['dropped']} dropped")
    extra = sp.get("sent", 0) - sp.get("scheduled", 0)
    stop = {True: ", then the stop", False: ", NO stop delivered"}.get(sp.get("stopped"), "")
    fed = sp.get("after_stop") or {}
    if fed:
        stop += (f", fed {fed.get('seconds', 0):g} s until landed" if fed.get("ended") == "landed"
                 else f", fed {fed.get('seconds', 0):g} s: {fed.get('ended')}")
    lines.append(f"  setpoints {sp.get('scheduled', 0)} of {sp.get('planned', 0)} planned sent "
                 f"(+{extra} unlock/descent{stop}); period jitter p50 {jit.get('p50', 0):.1f} ms, "
                 f"p99 {jit.get('p99', 0):.1f} ms, max {jit.get('max', 0):.1f} ms "
                 "on the flight clock")
    lines += _live_id_lines(summary)
    lines.append(f"  file {summary.get('file') or 'none: the session could not be saved'}")
    return lines


def _live_id_lines(summary: Mapping[str, Any]) -> list[str]:
    """The live identification's part of the summary (none without it)."""
    lid, cut = summary.get("live_id"), summary.get("excitation_cut")
    if not lid:
        return []
    lines = [f"  live id {lid['updates']} updates ({lid['skipped']} skipped, {lid['failed']} "
             f"failed), order {lid['order']}, past {lid['past']}, future {lid['future']}"]
    if lid.get("span_s") is not None:
        over = (f" over the last {lid['fit_window_s']:g} s (mean of the outputs; sysid "
                "compare scores the whole flight)" if lid.get("fit_window_s") else "")
        unstable = (" (unstable: it drifts off in any simulation; sysid identify on the "
                    "session chooses and stabilises a model)" if lid["max_pole"] > 1.0 else "")
        lines.append(f"    final model on {lid['span_s']:.1f} s of data: one-step fit "
                     f"{lid['fit_pct']:.1f} %{over}, max |pole| {lid['max_pole']:.4f}"
                     f"{unstable}, saved as {lid['model_file'] or '(not saved)'}")
    if cut:
        planned = float(summary.get("setpoints", {}).get("planned", 0)) * float(
            summary.get("setpoints", {}).get("period_s", 0.0))
        lines.append(f"    {cut['reason']}; excitation ended at {cut['at_s']:.1f} s, "
                     f"{cut['skipped_s']:.1f} s of flight saved ({planned - cut['skipped_s']:.1f}"
                     f" s instead of {planned:.1f} s planned)")
    conv = lid.get("convergence")
    # asked for, never reached, the excitation flown to its end (no abort, no failed engine)
    if (conv and lid.get("converged_at_s") is None and not cut and not summary.get("aborted")
            and not lid.get("error")):
        lines.append(f"    not converged: the poles never stayed within {conv['tolerance']:g} "
                     f"for {conv['duration_s']:g} s, so the whole excitation was flown (a "
                     "larger --converged-tol or a longer excitation; docs/live-id.md)")
    if lid.get("error"):
        lines.append(f"    live id: {lid['error']}")
    return lines


def _speed_in_uri() -> None:
    """``--speed`` (demo's option, and a guess at the simulator's) is refused with the place
    the speed goes; click would suggest ``--seed``, which changes the flight, not the speed."""
    if click.get_current_context().get_parameter_source("speed") is not (
            click.core.ParameterSource.DEFAULT):
        raise click.BadParameter("the simulator's speed is part of its URI: --uri "
                                 "'sim://0?speed=20' (or --emulated-radio-speed)",
                                 param_hint="--speed")


@click.command("fly")
@click.argument("plan")
@click.option("--uri", default=DEFAULT_URI, show_default=True,
              help="Crazyflie link: radio://..., usb://0, udp://127.0.0.1:19850, sim://0?speed=20.")
@click.option("--out", type=click.Path(file_okay=False, path_type=Path), default=Path("sessions"),
              show_default=True, help="Folder for the session file.")
@click.option("--name", "tag", default="", metavar="TAG",
              help="Tag for the file name (PLAN-TAG-TIME.h5) and the session's metadata, "
                   "e.g. validation.")
@click.option("--advance", type=click.IntRange(0, 1_000_000), default=None, metavar="CHIPS",
              help="Fly another PRBS realisation: every PRBS advanced this many chips in its "
                   "m-sequence (lags between axes kept), as demo's validation flight.")
@click.option("--seed", type=click.IntRange(1), default=None,
              help="Fly another PRBS realisation: the first PRBS starts from this register "
                   "state, the others keep their lags to it.")
@click.option("--view", type=click.Choice(["none", "rerun", "serve"]), default="none",
              show_default=True, help="Live view: Rerun viewer, web viewer, or none.")
@click.option("--port", "web_port", type=click.IntRange(0, 65535), default=9090,
              show_default=True, help="Web viewer port on 127.0.0.1 (--view serve; 0: any).")
@click.option("--max-rate", type=FiniteFloat(min=MAX_RATE_RANGE_DEG_S[0],
                                             max=MAX_RATE_RANGE_DEG_S[1]), default=None,
              help=f"Abort when a gyro axis exceeds this, deg/s ({MAX_RATE_RANGE_DEG_S[0]:g} "
                   f"to {MAX_RATE_RANGE_DEG_S[1]:g}, as the plan's safety.max_rate_deg_s) "
                   "[default: the plan's value, else 1000].")
@click.option("--timeout", "timeout_s", type=FiniteFloat(min=0.5), default=10.0,
              show_default=True,
              help="Seconds the vehicle may stay silent while connecting (a connection that "
                   "keeps answering may take up to 120 s in all).")
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON.")
@click.option("--arm", is_flag=True,
              help="Arm a Crazyflie that does not arm itself (a Crazyflie Brushless) before "
                   "take-off; without it such a vehicle is refused, nothing flown.")
@click.option("--emulated-radio", is_flag=True,
              help="Fly radio:// through an emulated Crazyradio PA to a simulated Crazyflie on "
                   "channel 80, 2M, E7E7E7E7E7 (cflib unchanged; docs/flying.md).")
@click.option("--emulated-radio-speed", type=FiniteFloat(min=0.1, max=20.0), default=1.0,
              show_default=True, help="Simulation speed behind --emulated-radio (x real time).")
@click.option("--live-id", is_flag=True,
              help="Identify a model while the excitation flies (the plan's [live_id] settings, "
                   "else motors -> gyro, order 8, past 60, future 17, every 1 s; "
                   "docs/live-id.md). On by itself when the plan has a [live_id] table.")
@click.option("--until-converged", is_flag=True,
              help="End the excitation once the live model's poles have settled "
                   "(--converged-tol over --converged-for), then fly the plan's landing. "
                   "Implies --live-id.")
@click.option("--converged-tol", type=FiniteFloat(min=0.0, min_open=True), default=None,
              help="Largest pole movement (z-plane distance) that counts as settled "
                   "[default: 0.01].")
@click.option("--converged-for", type=FiniteFloat(min=0.1), default=None, metavar="SECONDS",
              help="Flight time the poles must stay within --converged-tol [default: 3].")
@click.option("--speed", hidden=True, expose_value=False, callback=lambda *_: _speed_in_uri())
def command(plan: str, uri: str, out: Path, tag: str, advance: int | None, seed: int | None,
            view: str, web_port: int, max_rate: float | None, timeout_s: float,
            as_json: bool, arm: bool, emulated_radio: bool, emulated_radio_speed: float,
            live_id: bool, until_converged: bool, converged_tol: float | None,
            converged_for: float | None) -> None:
    """Fly a flight plan and record it to a session file.

    Connects, checks the log TOC and the battery, streams the plan's setpoints at its rate and
    lands. Ctrl-C, link loss or a limit stop the motors (after the plan's descent where it asks
    for one). PLAN is a path or a shipped plan's name.

    \b
    Examples:
      groundstation fly hover-check
      groundstation fly prbs-3axis --uri 'sim://0?speed=20' --out sessions --view rerun
      groundstation fly prbs-3axis --advance 500 --name validation   # validation flight
      groundstation fly hover-check --emulated-radio --emulated-radio-speed 10
      groundstation fly prbs-3axis --uri 'sim://0?speed=20' --live-id --until-converged
    """
    if advance is not None and seed is not None:
        raise click.UsageError("--advance and --seed both choose the PRBS; pass only one")
    if (converged_tol is not None or converged_for is not None) and not until_converged:
        raise click.UsageError("--converged-tol and --converged-for need --until-converged")
    d = Convergence()
    convergence = Convergence(tolerance=d.tolerance if converged_tol is None else converged_tol,
                              duration_s=d.duration_s if converged_for is None else converged_for)
    loaded = load_plan(plan)
    if converged_for is not None:  # --converged-for 3000 (ms): the whole excitation, no cut
        spans = [(p.start, p.start + p.duration) for p in loaded.compile().phases
                 if p.kind == "excitation"]
        if spans and converged_for >= spans[-1][1] - spans[0][0]:
            raise click.BadParameter(
                f"{converged_for:g} s is not shorter than the plan's excitation "
                f"({spans[-1][1] - spans[0][0]:.1f} s), so it could never end it early; it is "
                f"in seconds of flight (default {d.duration_s:g})", param_hint="--converged-for")
    if advance is not None:
        loaded = advance_prbs(loaded, chips=advance)
    elif seed is not None:
        loaded = reseed_prbs(loaded, seed=seed)
    check_tag(tag)
    check_uri(uri)  # before any viewer opens; fly_plan checks the file name before connecting
    missing = [p for p in (out, *out.parents) if not p.exists()]  # folders we will create
    check_folder(out)
    for warning in summarize(loaded, loaded.compile())["warnings"]:  # plan check's
        click.echo(f"warning: {shown_text(warning)}", err=True)
    bus: contextlib.AbstractContextManager[Any] = contextlib.nullcontext()
    if emulated_radio:
        from groundstation.sim.crazyradio_usb import emulated_radio as emulated

        bus = emulated(speed=emulated_radio_speed)
    try:
        with bus:
            result, url = _fly(loaded, uri=uri, out=out, tag=tag, view=view, web_port=web_port,
                               max_rate=max_rate, timeout_s=timeout_s, as_json=as_json,
                               arm=arm,
                               live_id=live_id or until_converged or loaded.live_id is not None,
                               convergence=convergence if until_converged else None)
    except BaseException:
        for folder in missing:  # nothing recorded (no radio, no view): leave no empty folder
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        raise
    unwritten = None
    try:
        if as_json:
            click.echo(json.dumps(result.summary, indent=2))
        else:
            click.echo("\n".join(map(shown_text, summary_lines(result.summary))))
    except OSError as exc:  # the terminal closed (the hang-up that aborted the flight?): the
        if exc.errno in NO_ROOM:  # exit status below still tells how the flight ended;
            drop_failing_stdout()  # a full disk under a redirection says so after it
            unwritten = exc.strerror
        elif not output_gone(exc):
            raise
        url = None
    if result.escaped is not None:  # a listener asked to end the program: no serving on
        url = None
    if url and sys.stdin.isatty():
        _keep_serving(url)
    elif url:
        click.echo("the web viewer stops with this command (not started from a terminal); "
                   f"groundstation replay {result.path} --view serve shows the flight again",
                   err=True)
    lost = result.summary.get("file_error")
    if lost:  # the session lost, or only part of a flight that was not aborted
        raise GroundStationError(f"flight aborted: {result.cause}; {lost}" if result.cause
                                 else lost)
    _listener_exit(result)
    result.raise_if_aborted()
    if unwritten:
        raise GroundStationError(f"cannot write the flight's summary to standard output "
                                 f"({unwritten}); the session is {result.path}")


def _listener_exit(result: FlightResult) -> None:
    """What a listener's ``SystemExit`` (or ``KeyboardInterrupt``) means for ``fly``'s exit,
    once the summary is out.

    A ``SystemExit`` that ended the flight (its cause, naming the listener and the code) is an
    aborted flight, whatever its code: exit 2 and the one line of any abort (the code, even 0,
    would read as the listener's verdict on the flight; a script tells an aborted flight by
    2). One raised after the landing (the flight was whole) keeps a code of 0 (``None``) as
    exit 0 and turns any other into one line and exit 2. A ``KeyboardInterrupt`` (or any other
    exception that is no ``Exception``) goes on up as before: Ctrl-C's line and exit 130."""
    escaped = result.escaped
    if escaped is None:
        return
    if not isinstance(escaped, SystemExit):
        raise escaped
    if not result.aborted and escaped.code not in (None, 0):
        raise GroundStationError(f"a listener exited (SystemExit: {escaped.code}) after the "
                                 f"landing; session saved to {result.path}")


def _fly(plan: Plan, *, uri: str, out: Path, tag: str, view: str, web_port: int,
         max_rate: float | None, timeout_s: float, as_json: bool, arm: bool, live_id: bool,
         convergence: Convergence | None) -> tuple[FlightResult, str | None]:
    """Check the live identification, open the view (before connecting: either failing stops
    us here), fly."""
    listeners: list[FlightListener] = []
    url, status = None, None
    lid = live_id_listener(plan, convergence=convergence) if live_id else None
    if view != "none":
        shown = open_view(mode=view, name=plan.name, web_port=web_port)
        listeners.append(shown)
        url = getattr(shown, "url", None)
        if url:
            click.echo(f"Rerun web viewer: {url}", err=True)
        if lid is not None and getattr(shown, "rec", None) is not None:
            from groundstation.liveid_view import LiveIdView  # Rerun only with a view

            lid.observers.append(LiveIdView(rec=shown.rec))
    if lid is not None:
        listeners.append(lid)
        status = lambda: lid.status  # noqa: E731
    if sys.stdout.isatty() and not as_json:
        listeners.append(ProgressListener(duration_s=plan.duration, status=status))
    else:  # nohup, CI logs, --json: plain lines on stderr
        listeners.append(PlainProgress(duration_s=plan.duration, status=status))
    result = fly_plan(plan=plan, out=out, uri=uri, listeners=listeners, tag=tag, arm=arm,
                      limits=None if max_rate is None else RateLimits(max_rate_deg_s=max_rate),
                      connect_timeout_s=timeout_s,
                      tick_hook=lid.in_step(real_time_s=1.0 / plan.setpoint_rate_hz)
                      if lid is not None and _flat_out(uri) else None,
                      reraise=False)  # a listener's SystemExit: the summary first
    return result, url


def _flat_out(uri: str) -> bool:
    """Whether ``uri`` is a simulator running flat out (``sim://...?speed=inf``): its clock
    has no wall-time meaning, so the live identification is kept in step with it."""
    if not uri.startswith("sim://"):
        return False
    from groundstation.sim.uri import parse_uri

    try:
        return math.isinf(parse_uri(uri).speed)
    except GroundStationError:  # a bad URI: the connection says so
        return False


def _keep_serving(url: str) -> None:
    """The web viewer lives as long as this process: keep it up after landing until Ctrl-C."""
    from cfcommon.rerun import serve_until_interrupted  # rerun loads only when serving

    click.echo(f"still serving the flight at {url}; Ctrl-C to quit", err=True)
    serve_until_interrupted()
    click.echo("", err=True)
