"""``groundstation replay SESSION``: a recorded flight in the same Rerun view as a live one.

The session's streams are declared to :class:`groundstation.live.RerunView` with the specs
they were recorded with, then each stream is sent as one block (``send_columns`` per channel),
so a 5-minute flight replays in well under a second. A damaged or crash-truncated session is
replayed as far as it reads, and each of its problems (those ``groundstation info`` lists) is
logged as a warning naming the file.
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import click

from cfcommon.cli import check_output
from cfcommon.rerun import serve_until_interrupted
from cfsession import Session, open_session, warn_problems
from cfsession.schema import Field, StreamSpec
from groundstation.live import RerunView, open_view

__all__ = ["command", "replay_session", "specs_of"]

log = logging.getLogger(__name__)


def specs_of(session: Session) -> list[StreamSpec]:
    """The stream specs a session was written with (fields, dtypes, units, sources)."""
    specs = []
    for name, s in session.streams.items():
        dtype = s.data.dtype
        fields = tuple(
            Field(f, dtype.fields[f][0].str, s.units.get(f, ""), s.sources.get(f, ""))
            for f in dtype.names
        )
        specs.append(StreamSpec(name=name, kind=s.kind, fields=fields, period_s=s.period_s))
    return specs


def replay_session(*, session: Session, view: RerunView) -> dict[str, int]:
    """Send every non-empty stream of ``session`` through ``view`` and end it.

    Returns the rows shown per stream: a row with no usable time (not finite, beyond what
    Rerun's time columns hold) is left out and not counted (``view.untimed_rows``).
    """
    meta = dict(session.meta) | {"problems": list(session.problems)}
    specs = [s for s in specs_of(session) if len(session[s.name])]  # no empty panels
    view.begin(streams=specs, metadata=meta)
    for spec in specs:
        view.send_block(spec.name, session[spec.name].data)
    stored = session.json_meta("summary", {})  # a file from elsewhere: maybe no JSON object
    summary = (stored if isinstance(stored, dict) else {"summary": stored}) | {
        "duration_s": session.duration}
    view.end(summary=summary)
    return dict(view.sent_rows)


def _left_out(view: RerunView) -> str:
    """``; N rows with no usable time left out`` when the view left rows out, else ``""``."""
    n = sum(view.untimed_rows.values())
    return f"; {n} rows with no usable time left out" if n else ""


@click.command("replay", short_help="Show a recorded session in Rerun, or write it to .rrd.")
@click.argument("session", type=click.Path(path_type=Path))
@click.option("--rrd", "rrd", type=click.Path(path_type=Path, dir_okay=False), default=None,
              help="Write the view to this .rrd file (open it later with `rerun FILE`); an "
                   "existing file needs --force.")
@click.option("--force", is_flag=True, help="Replace the --rrd file if it exists.")
@click.option("--view", "mode", type=click.Choice(["rerun", "serve"]), default=None,
              help="rerun: native viewer (web viewer without a display); serve: web viewer "
                   "on 127.0.0.1. Default: rerun.")
@click.option("--port", "web_port", type=click.IntRange(0, 65535), default=9090,
              show_default=True, help="Web viewer port on 127.0.0.1 (0: any free port).")
def command(session: Path, rrd: Path | None, force: bool, mode: str | None,
            web_port: int) -> None:
    """Show SESSION (an .h5 flight session) in Rerun as the live view showed it.

    \b
    Examples:
      groundstation replay sessions/prbs-3axis-20261122T100000Z.h5
      groundstation replay flight.h5 --rrd flight.rrd
      groundstation replay flight.h5 --view serve --port 9091
    """
    if rrd is not None and mode is not None:
        raise click.UsageError("--rrd writes a file and --view shows a viewer; pass only one")
    if rrd is not None:  # before any work: never the session itself, nor a file, unforced
        check_output(rrd, option="--rrd", suffixes=(".rrd",), inputs=[session], overwrite=force,
                     force_flag="--force")
    s = open_session(session)
    warn_problems(s, log)  # replayed as far as it reads: say what is missing
    t0 = time.perf_counter()
    view = open_view(mode="save" if rrd else mode or "rerun", name=session.stem, rrd_path=rrd,
                     web_port=web_port)
    counts = replay_session(session=s, view=view)
    replayed = f"{sum(counts.values())} rows from {len(counts)} streams{_left_out(view)}"
    log.info("replayed %s in %.2f s", replayed, time.perf_counter() - t0)
    if rrd is not None:
        click.echo(f"wrote {rrd} ({replayed})")
        return
    if view.url:
        click.echo(f"Rerun web viewer: {view.url}  (Ctrl-C to stop serving)")
        serve_until_interrupted()
