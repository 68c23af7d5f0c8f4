"""The ``sysid`` command line: identify, compare, order, sweep and export from session files.

Sessions are read through :mod:`sysid.session_io` (channels, window, ZOH grid). User mistakes
(:class:`~sysid.errors.SysIdError`, session-file errors, missing files) print one line and exit
with code 2, never a traceback. ``--json`` prints a machine-readable result on stdout; tables
and progress are for people (progress goes to stderr).
"""

from __future__ import annotations

import contextlib
import json
import logging
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import click

from cfcommon.cli import (
    FiniteFloat,
    check_output,
    names_a_file,
    output_table,
    setup_logging,
    shown_markup,
)
from sysid.batch import (
    GROUP_BY,
    GroupBy,
    check_model_paths,
    group_sessions,
    model_path,
    name_list,
    run_batch,
)
from sysid.batch_resume import resumable, write_config
from sysid.cli_compare import compare_cmd, resid
from sysid.cli_identify import identify
from sysid.cli_options import (
    FOCUS_OPTION,
    FORCE_OPTION,
    METHOD_OPTION,
    STABILITY_OPTION,
    fixed_option,
    method_chosen,
    method_options,
    model_options,
)
from sysid.cli_order import order_command
from sysid.cli_progress import progress
from sysid.cli_support import (
    GRID_FORMS,
    JSON_OPTION,
    MAX_WINDOW_S,
    Group,
    console,
    load_groups,
    parse_grid,
    parse_window,
    pole_table,
    session_options,
)
from sysid.cli_sweep import sweep_command
from sysid.errors import ClusterError, DataError, ParameterError
from sysid.model import load_model
from sysid.realize import software_versions
from sysid.session_io import read_metadata

__all__ = ["main", "parse_grid", "parse_window", "pole_table"]

log = logging.getLogger(__name__)


@click.group(cls=Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="cf-sysid", prog_name="sysid")
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
def main(verbose: int) -> None:
    """Closed-loop subspace identification of flight sessions (IEM, PARSIM-K; PO-MOESP).

    \b
    Examples:
      sysid identify flight1.h5 flight2.h5 --order 8 --out model.h5
      sysid compare model.h5 validation.h5 --window-s 5 --horizon 10
    """
    setup_logging(verbose=verbose)


main.add_command(compare_cmd)
main.add_command(resid)
main.add_command(identify)

SCHEDULER_OPTION = click.option(
    "--scheduler", metavar="tcp://HOST:PORT",
    help="Run on this Dask distributed scheduler (pip install 'cf-sysid[dask]'); the data are "
         "sent once per worker. --workers is then ignored.")


@contextlib.contextmanager
def scheduler_client(address: str | None) -> Iterator[Any]:
    """A Dask client of ``address`` (None: no cluster), its dashboard printed on stderr.

    Every fault of the cluster is one line (:mod:`sysid.cluster`): an address that does not
    answer the Dask handshake within the connect timeout, a scheduler that has had no worker
    for that long at the start, and during the run a lost scheduler, or no workers for the
    worker wait (warned of on stderr when it begins). Dask's own log shows with ``-v``."""
    if address is None:
        yield None
        return
    from sysid.cluster import (
        connect,
        connect_timeout_s,
        dashboard_link,
        quiet_dask_log,
        wait_for_workers,
        watching,
        worker_count,
        worker_wait_s,
    )

    label = f"--scheduler {address}"
    timeout, wait = connect_timeout_s(), worker_wait_s()
    with quiet_dask_log():
        client = connect(address, timeout_s=timeout)
        try:
            link = dashboard_link(client, label=label)
            n = worker_count(client, label=label)
            click.echo(f"dask: {address}, {n} worker(s)"
                       + (f", dashboard {link}" if link else ", no dashboard")
                       + ("" if n else f"; waiting up to {timeout:g} s for one"), err=True)
            if not n:
                n = wait_for_workers(client, timeout_s=timeout, label=label)
                click.echo(f"dask: {n} worker(s)", err=True)
            with watching(label=label, worker_wait_s=wait,
                          notify=lambda msg: click.echo(f"warning: {msg}", err=True)):
                yield client
        finally:
            with contextlib.suppress(Exception):  # a lost scheduler: nothing left to close
                client.close(timeout=timeout)


@main.command()
@click.argument("session", type=click.Path(path_type=Path))
@METHOD_OPTION
@fixed_option("past",
              help="Past horizon, samples (default: the largest of the scaled default grid).")
@fixed_option("future",
              help="Future horizon, samples (default: as --past).")
@click.option("--show", default=20, show_default=True, type=click.IntRange(min=2),
              help="How many singular values to list.")
@session_options
@JSON_OPTION
def order(session: Path, method: str, past: int | None, future: int | None, show: int,
          as_json: bool, **opts: Any) -> None:
    """Singular values of the order-selection SVD, AIC/AICc/BIC of the models of orders
    1..min(--show, 12), the order each rule picks and a suggestion naming its rule
    (docs/sysid.md).

    The values and models are those of --method (the registry of sysid identify), and no
    order is scored or suggested beyond what it identifies at these horizons; an order it
    fails to identify there is listed with its reason and neither scored nor suggested. The
    gap rule picks the n maximising log10(s_n / s_n+1) among the first --show values. It is
    the suggestion when clear: n >= 2 and a drop of at least a factor of 2 (0.3 decades),
    and, if under a factor of 10 (1 decade), AIC, AICc or BIC picking no more than n states.
    A largest gap right after s_1 is degenerate (one dominant direction), a smaller one no
    cut: BIC's order is suggested then, as it is when the horizons cap the rank or order n
    cannot be identified. The information criteria score orders up to 12: a BIC at 12 may
    lie beyond (a larger --show does not raise it). Validation on held-out data (sysid
    identify without --order) judges better than either. Without --past/--future the
    horizons are the largest of the default grid (three and one and a half times the data's
    memory, the lag of the best ARX model by AICc, or what the data allow).

    \b
    Example:
      sysid order flight.h5 --past 60 --future 17
    """
    order_command(session, method=method, past=past, future=future, show=show,
                  as_json=as_json, **opts)


@main.command("sweep")
@click.argument("session", type=click.Path(path_type=Path))
@METHOD_OPTION
@click.option("--pasts", help=f"{GRID_FORMS} (default: scaled to the data rate and length, "
                              "see docs/sysid.md).")
@click.option("--futures", help=f"{GRID_FORMS}, each >= 2 (default: scaled).")
@click.option("--orders", help=f"{GRID_FORMS} (default: 2 to 12).")
@click.option("--workers", default=1, show_default=True, type=click.IntRange(1, 64),
              help="Worker processes (Ctrl-C stops them all).")
@SCHEDULER_OPTION
@click.option("--validate", "validate", multiple=True, type=click.Path(path_type=Path),
              help="Score on this session (repeatable; default: the last 30 % of each "
                   "experiment, identified on the rest).")
@click.option("--horizon", type=click.IntRange(min=1), help="Score by k-step prediction.")
@click.option("--window-s", type=FiniteFloat(min=0, min_open=True, max=MAX_WINDOW_S),
              help="Score by simulation over windows of this many seconds (default: 12 "
                   "times the data's memory, at least 20 samples; see docs/sysid.md).")
@click.option("--top", default=10, show_default=True, type=click.IntRange(min=1),
              help="Candidates listed (and in --json).")
@model_options(out_help="Save the selected model, identified again on all the session's data "
                        "(or the model the sweep scored, when that refit has a pole outside "
                        "the unit circle or fails: the saved line says which).")
def sweep_cmd(session: Path, method: str, pasts: str | None, futures: str | None,
              orders: str | None, workers: int, scheduler: str | None,
              validate: tuple[Path, ...], horizon: int | None, window_s: float | None,
              top: int, focus: str | None, stability: str, out: Path | None, force: bool,
              as_json: bool, rrd: Path | None, **opts: Any) -> None:
    """Identify a model for every (past, future, order), rank them by score, choose one.

    The choice is that of `sysid identify` without --past/--future/--order (sysid.auto):
    the same held-out split, default grid, score and rule, so on the same session both
    choose the same past, future, order and focus. The score is the mean of the per-channel
    fits floored at 0 % (one channel no model can predict cannot decide the ranking); the
    smallest order within one standard error of the best stable score (over blocks of the
    held-out data, at least 0.1 points) is chosen. Without --method PARSIM-K is tried beside
    IEM at the chosen horizons (the smaller order that scores as well wins, IEM on a tie).
    Without --focus the grid runs once per
    focus and the focus whose choice scores best is taken. The report lists the best --top
    candidates with their fits, warns when the choice is at the edge of the grid or when the
    held-out data are too few to rank the models, and --out saves the chosen model identified
    again on all the data (unless that fails or tips a pole outside the unit circle: then the
    model the sweep scored, as a warning and the saved line say). Models that cannot be
    identified are counted with their reasons; when none can, or none is stable, the command
    exits with 2.

    \b
    Example:
      sysid sweep flight.h5 --pasts 20:80:10 --futures 5:25:4 --orders 6,8,10 \\
        --validate other_flight.h5 --window-s 5 --workers 2 --out model.h5
      sysid sweep flight.h5 --scheduler tcp://10.0.0.5:8786   # on a Dask cluster
    """
    meth, options = method_options(method, focus=focus, stability=stability)
    sweep_command(session=session, method=meth, options=options, choose_focus=focus is None,
                  choose_feedthrough="open-loop", choose_method=method_chosen(),
                  pasts=pasts, futures=futures, orders=orders, workers=workers,
                  connect=lambda: scheduler_client(scheduler), validate=validate,
                  horizon=horizon, window_s=window_s, top=top, out=out, force=force,
                  as_json=as_json, rrd=rrd, opts=opts)


@main.command()
@click.argument("sessions", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out_dir", required=True,
              type=click.Path(file_okay=False, path_type=Path),
              help="Folder for one model per group (GROUP.h5) and summary.csv/summary.json.")
@click.option("--group-by", type=click.Choice(GROUP_BY), default="session", show_default=True,
              help="One model per session, vehicle (uri), UTC day, plan name, or of all.")
@METHOD_OPTION
@fixed_option("order",
              help="Fix the order (default: chosen).")
@fixed_option("past",
              help="Fix the past horizon, samples.")
@fixed_option("future",
              help="Fix the future horizon, samples.")
@click.option("--workers", default=1, show_default=True, type=click.IntRange(1, 64),
              help="Worker processes for each group's choice of horizons and order.")
@SCHEDULER_OPTION
@FOCUS_OPTION
@STABILITY_OPTION
@session_options
@FORCE_OPTION
@click.option("--resume", is_flag=True,
              help="Finish an interrupted batch in --out: run the groups it did not identify "
                   "(not run, or failed), keeping the others; the same sessions and options, "
                   "or it refuses.")
@JSON_OPTION
def batch(sessions: tuple[Path, ...], out_dir: Path, group_by: GroupBy, method: str,
          order: int | None, past: int | None, future: int | None, workers: int,
          scheduler: str | None, focus: str | None, stability: str, force: bool,
          resume: bool, as_json: bool, **opts: Any) -> None:
    """Identify one model per group of sessions, all with one configuration.

    Groups come from the sessions' metadata (--group-by; docs/sysid.md names them). Each
    group's horizons and order are chosen by validation on held-out data, as `identify` does,
    unless fixed; the method and focus too (unless --method/--focus), even with all three
    fixed, so that every row has a held-out score: `identify` with all three fixed makes
    IEM's prediction-focus model from all the data instead. A group that fails is a row with
    its reason; the batch goes on, and exits with 1 when some groups failed (2 when all did).
    The summary is rewritten as each group finishes: Ctrl-C keeps the finished groups, and so
    does a --scheduler cluster that fails mid-run (one line names the groups not run); the
    same command with --resume then runs those (and any that failed).

    \b
    Examples:
      sysid batch logs/*.h5 --out models --group-by vehicle
      sysid batch logs/*.h5 --out models --scheduler tcp://10.0.0.5:8786
      sysid batch logs/*.h5 --out models --group-by vehicle --resume
    """
    if names_a_file(out_dir):
        raise ParameterError(f"--out {out_dir}: names a model file, but batch writes one model "
                             "per group (and its summary) into a folder; give a folder, e.g. "
                             f"--out {out_dir.with_suffix('')}")
    if resume and force:
        raise ParameterError("--resume keeps the finished groups, --force replaces them; "
                             "give one of them")
    summary = out_dir / "summary.json"
    if summary.exists() and not (force or resume):
        raise ParameterError(f"--out {out_dir}: holds a batch summary already; pass --resume "
                             "to finish it, --force to replace it, or choose another folder")
    meth, options = method_options(method, focus=focus, stability=stability)
    grid = {k: [v] for k, v in (("pasts", past), ("futures", future), ("orders", order))
            if v is not None}
    groups, bad = group_sessions(list(sessions), by=group_by,
                                 read_meta=read_metadata)
    check_model_paths(groups, out_dir=out_dir, rows=bad)  # never over an input session
    config = {"group_by": group_by, "method": None if method_chosen() else method,
              "order": order, "past": past, "future": future, "focus": focus,
              "stability": stability, **opts, "sysid_version": software_versions()["cf-sysid"]}
    finished = resumable(out_dir, groups, config) if resume else {}
    if resume:
        log.info("resuming %s: %d of %d group(s) finished", out_dir, len(finished), len(groups))
    taken = [model_path(out_dir, name) for name in groups if model_path(out_dir, name).exists()]
    if taken and not (force or resume):
        more = f" (and {len(taken) - 1} more model file(s))" if len(taken) > 1 else ""
        raise ParameterError(f"--out {out_dir}: {taken[0].name} exists{more}; pass --force to "
                             "replace the models or choose another folder")
    if not resume and out_dir.is_dir():  # a run stopped before its first row: no old summary
        for name in ("summary.json", "summary.csv"):
            (out_dir / name).unlink(missing_ok=True)
    write_config(out_dir, config, sessions=sessions)
    rows: list[Any] = []
    try:
        with scheduler_client(scheduler) as client, \
                progress("batch", total=len(groups) - len(finished), quiet=as_json) as update:
            rows = run_batch(groups, out_dir=out_dir, rows=bad, finished=finished,
                             load=lambda paths: load_groups(paths, opts=opts),
                             method=meth, options=options, grid=grid, workers=workers,
                             client=client, progress=update,
                             group_progress=lambda g, d, t: update(detail=f"{g}: {d}/{t} models"),
                             choose_focus=focus is None, choose_feedthrough="open-loop",
                             choose_method=method_chosen())
    except ClusterError as exc:
        if "not run:" not in str(exc):
            raise
        raise type(exc)(f"{exc} (the same command with --resume runs them)") from None
    except KeyboardInterrupt:
        unread = {r.group for r in bad}  # rows from the start: they did not run
        ended = {r["group"] for r in json.loads(summary.read_text())
                 if r["group"] in groups and r["group"] not in unread} \
            if summary.exists() else set()
        left = [name for name in groups if name not in ended]
        click.echo(f"interrupted: {len(ended)} finished group(s) kept in {summary} and "
                   f"{out_dir / 'summary.csv'}"
                   + (f"; {len(left)} group(s) not run: {name_list(left)} (the same "
                      "command with --resume runs them)" if left else ""), err=True)
        sys.exit(130)
    failed = [r for r in rows if r.error is not None]
    if as_json:
        click.echo(json.dumps({"out": str(out_dir), "group_by": group_by,
                               "groups": [r.record() for r in rows]}, indent=1))
    else:
        con = console()
        table = output_table("group", "flights", "past", "future", "order", "method", "focus",
                             "score [%]", "stable", "model / reason", console=con,
                             title=f"{len(rows)} group(s), {len(failed)} failed")
        for r in rows:
            table.add_row(r.group, str(r.flights), *(str(v) if v is not None else "-"
                                                     for v in (r.past, r.future, r.order,
                                                               r.method, r.focus)),
                          "-" if r.score is None else f"{r.score:.1f}",
                          "-" if r.stable is None else str(r.stable),
                          r.error or r.model or "")
        con.print(table)
        for r in rows:  # what identify would print for the group
            for w in r.warnings:
                con.print(f"[yellow]warning:[/] {shown_markup(r.group)}: {shown_markup(w)}")
        con.print(f"summary: {out_dir / 'summary.csv'}, {summary}")
    if rows and len(failed) == len(rows):
        raise DataError(f"every one of the {len(rows)} group(s) failed; first: "
                        f"{failed[0].group}: {failed[0].error}")
    if failed:  # a script must see it: exit 1, the finished groups' models kept
        click.echo(f"error: {len(failed)} of the {len(rows)} group(s) failed; first: "
                   f"{failed[0].group}: {failed[0].error}", err=True)
        sys.exit(1)


@main.command()
@click.argument("model_path", metavar="MODEL", type=click.Path(path_type=Path))
@click.option("--format", "fmt", type=click.Choice(["json", "mat"]),
              help="Output format (default: the suffix of --out).")
@click.option("--out", type=click.Path(dir_okay=False, path_type=Path),
              help="Output file (default: MODEL with the format's suffix).")
@FORCE_OPTION
def export(model_path: Path, fmt: str | None, out: Path | None, force: bool) -> None:
    """Write a model file as JSON or MATLAB .mat (A, B, C, D, K, Ts, names, units).

    \b
    Examples:
      sysid export model.h5 --out model.mat     (the format from the suffix)
      sysid export model.h5 --format json       (writes model.json)
    """
    if fmt is None:
        fmt = out.suffix.lower().lstrip(".") if out is not None else ""
        if fmt not in ("json", "mat"):
            raise click.UsageError("give --format json or mat, or an --out file ending in "
                                   ".json or .mat", ctx=click.get_current_context())
    model = load_model(model_path)
    target = out or model_path.with_suffix(f".{fmt}")
    check_output(target, option="--out", suffixes=(f".{fmt}",), inputs=(model_path,),
                 overwrite=force, force_flag="--force")
    model.save(target)
    click.echo(f"wrote {target}")
