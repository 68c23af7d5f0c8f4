"""Identify many sessions, or groups of flights, with one configuration (``sysid batch``).

**Groups.** Sessions are grouped by a key read from each session's metadata; one model is
identified per group (its sessions are its experiments):

- ``session`` (default): every session is its own group, named after its file (``f3``);
- ``vehicle``: the ``vehicle`` attribute when present, else the radio ``uri``
  (``radio-0-80-2M-E7E7E7E7E7``);
- ``day``: the UTC day the session started (``2026-11-23``);
- ``plan``: the flight plan's name (``plan_name``, e.g. ``roll-prbs``);
- ``all``: one group of every session (``all``).

A name is the key with every character other than letters, digits, ``.``, ``_`` and ``-``
replaced by ``-``; a session without the key falls in ``unknown-vehicle`` (``-day``,
``-plan``). The model of group G is ``DIR/G.h5``.

**Each group** is identified by :func:`sysid.auto.select` (no knobs: held-out validation,
the default grid) with the given past/future/order fixing those axes. A group that fails
(unreadable session, too little data, no stable model) becomes a row with its one-line reason;
the batch goes on. The summary (``summary.csv`` and ``summary.json``) is rewritten as each
group finishes, so an interrupted batch keeps every finished group.

**Resuming** an interrupted batch (``sysid batch --resume``): :mod:`sysid.batch_resume`.
"""

from __future__ import annotations

import contextlib
import csv
import json
import logging
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from sysid.auto import select
from sysid.data import IOData
from sysid.errors import ClusterError, ParameterError, SysIdError, first_line
from sysid.methods import Method, Options
from sysid.session_io import SessionFileError, unique_name

__all__ = ["GROUP_BY", "BatchRow", "GroupBy", "check_model_paths", "group_sessions",
           "make_out_folder", "model_path", "name_list", "run_batch", "write_summary"]

log = logging.getLogger(__name__)

GroupBy = Literal["session", "vehicle", "day", "plan", "all"]
GROUP_BY: tuple[str, ...] = ("session", "vehicle", "day", "plan", "all")


@dataclass
class BatchRow:
    """One group's outcome: its model and validation fits, or the reason it failed."""

    group: str
    sessions: list[str]
    flights: int = 0
    past: int | None = None
    future: int | None = None
    order: int | None = None
    method: str | None = None
    focus: str | None = None
    poles: list[complex] = field(default_factory=list)
    outputs: list[str] = field(default_factory=list)
    fit: list[float] = field(default_factory=list)
    score: float | None = None
    stable: bool | None = None
    model: str | None = None
    error: str | None = None
    warnings: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @classmethod
    def from_record(cls, rec: dict[str, Any]) -> BatchRow:
        """The row :meth:`record` wrote (``summary.json``, a file from elsewhere): ``KeyError``,
        ``TypeError`` or ``ValueError`` for anything else (a number that is not finite, a
        ``stable`` that is not true, false or null)."""
        def number(value: Any, kind: type = float) -> Any:
            if isinstance(value, bool) or not np.isfinite(float(value)):
                raise ValueError(f"{value!r} is not a finite number")
            if kind is int and float(value) != int(value):
                raise ValueError(f"{value!r} is not an integer")
            return kind(value)

        def opt(key: str, read: Callable[[Any], Any]) -> Any:
            return None if rec[key] is None else read(rec[key])

        if rec["stable"] not in (True, False, None):
            raise ValueError(f"stable is {rec['stable']!r}")
        return cls(group=str(rec["group"]), sessions=[str(s) for s in rec["sessions"]],
                   flights=number(rec["flights"], int),
                   past=opt("past", lambda v: number(v, int)),
                   future=opt("future", lambda v: number(v, int)),
                   order=opt("order", lambda v: number(v, int)),
                   method=opt("method", str), focus=opt("focus", str),
                   poles=[complex(number(re_), number(im)) for re_, im in rec["poles"]],
                   outputs=[str(o) for o in rec["outputs"]],
                   fit=[number(f) for f in rec["validation_fit_percent"]],
                   score=opt("score_percent", number), stable=rec["stable"],
                   model=opt("model", str), error=opt("error", str),
                   warnings=[str(w) for w in rec["warnings"]], seconds=number(rec["seconds"]))

    def record(self) -> dict[str, Any]:
        return {"group": self.group, "sessions": self.sessions, "flights": self.flights,
                "past": self.past, "future": self.future, "order": self.order,
                "method": self.method, "focus": self.focus,
                "poles": [[float(p.real), float(p.imag)] for p in self.poles],
                "outputs": self.outputs, "validation_fit_percent": self.fit,
                "score_percent": self.score, "stable": self.stable, "model": self.model,
                "error": self.error, "warnings": self.warnings,
                "seconds": round(self.seconds, 3)}


def _safe(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", text).strip("-.") or "unnamed"


def _key(path: Path, meta: dict[str, Any], by: GroupBy) -> str:
    if by == "all":
        return "all"
    if by == "session":
        return _safe(path.stem)
    value = {"vehicle": meta.get("vehicle") or meta.get("uri"),
             "day": str(meta.get("start_time_iso") or "")[:10],
             "plan": meta.get("plan_name")}[by]
    return _safe(str(value)) if value else f"unknown-{by}"


def group_sessions(paths: Sequence[Path], *, by: GroupBy,
                   read_meta: Callable[[Path], dict[str, Any]]
                   ) -> tuple[dict[str, list[Path]], list[BatchRow]]:
    """``({group: sessions}, rows of sessions whose metadata cannot be read)``, groups in
    order of first appearance; two sessions with the same file stem get ``-2``, ``-3`` ..."""
    groups: dict[str, list[Path]] = {}
    bad = []
    for path in paths:
        try:
            meta = read_meta(path) if by not in ("all", "session") else {}
        except Exception as exc:  # any unreadable file is one failed row, never the end
            bad.append(BatchRow(group=_safe(path.stem), sessions=[str(path)],
                                error=first_line(exc)))
            continue
        key = _key(path, meta, by)
        if by == "session":
            key = unique_name(key, groups)
        groups.setdefault(key, []).append(path)
    return groups, bad


def _log_unexpected(group: str, exc: Exception) -> None:
    """A failure that is not a user error (a bug, a lost worker) keeps its traceback in the log."""
    if not isinstance(exc, (SysIdError, SessionFileError, OSError, ValueError,
                            np.linalg.LinAlgError)):
        log.error("group %s failed unexpectedly", group, exc_info=exc)


def identify_group(groups: list[list[IOData]], *, method: Method, options: Options,
                   grid: dict[str, list[int]], workers: int = 1,
                   choose_focus: bool = False,
                   choose_feedthrough: bool | Literal["open-loop"] = False,
                   choose_method: bool = False,
                   progress: Callable[[int, int], None] | None = None) -> dict[str, Any]:
    """Select and identify one group's model (:func:`sysid.auto.select`, with the focus
    chosen too when ``choose_focus`` and a direct term tried as ``choose_feedthrough`` says,
    as ``sysid identify`` does); runs anywhere (``progress(models done, models)`` only
    here)."""
    from sysid.sweep import one_blas_thread

    with one_blas_thread():  # the same bits locally and on a Dask worker (sysid.sweep)
        sel = select(groups, method=method, options=options, workers=workers,
                     choose_focus=choose_focus, choose_feedthrough=choose_feedthrough,
                     choose_method=choose_method, progress=progress, **grid)
    return {"model": sel.model, "past": sel.best.past, "future": sel.best.future,
            "order": sel.best.order, "focus": sel.model.provenance.get("focus"),
            "method": sel.model.provenance.get("method"),
            "fit": [float(f) for f in sel.best.fit], "score": sel.best.score,
            "stable": sel.model.is_stable, "outputs": list(sel.model.output_names),
            "warnings": list(sel.warnings)}


def write_summary(rows: Sequence[BatchRow], out_dir: Path) -> None:
    """``summary.json`` and ``summary.csv`` in ``out_dir`` (each replaced atomically)."""
    records = [r.record() for r in rows]
    tmp = out_dir / ".summary.json.tmp"
    tmp.write_text(json.dumps(records, indent=1))
    tmp.replace(out_dir / "summary.json")
    tmp = out_dir / ".summary.csv.tmp"
    with tmp.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["group", "sessions", "flights", "past", "future", "order", "method",
                    "focus", "poles", "outputs",
                    "validation_fit_percent", "score_percent", "stable", "model", "error",
                    "warnings", "seconds"])
        for r in rows:
            w.writerow([r.group, ";".join(r.sessions), r.flights, _cell(r.past),
                        _cell(r.future), _cell(r.order), r.method or "", r.focus or "",
                        ";".join(f"{p.real:.6g}{p.imag:+.6g}j" for p in r.poles),
                        ";".join(r.outputs), ";".join(f"{f:.3f}" for f in r.fit),
                        "" if r.score is None else f"{r.score:.3f}", _cell(r.stable),
                        r.model or "", r.error or "", " | ".join(r.warnings),
                        f"{r.seconds:.3f}"])
    tmp.replace(out_dir / "summary.csv")


def make_out_folder(out_dir: Path) -> None:
    """Make ``out_dir`` (and its parents) unless it exists; :class:`ParameterError` when it is
    a file."""
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise ParameterError(f"--out {out_dir}: exists and is not a folder; choose a folder "
                             "for the models and the summary") from None


def _cell(value: Any) -> str:
    return "" if value is None else str(value)


def _group_task(groups: list[list[IOData]], **kwargs: Any) -> dict[str, Any]:
    """:func:`identify_group` timed where it runs (here or on a Dask worker): its result with
    ``seconds``; a failure carries its seconds as ``sysid_seconds`` (an exception's attributes
    travel with it from a worker)."""
    t0 = time.perf_counter()
    try:
        out = identify_group(groups, **kwargs)
    except Exception as exc:
        with contextlib.suppress(Exception):  # an exception that takes no attributes
            exc.sysid_seconds = time.perf_counter() - t0  # type: ignore[attr-defined]
        raise
    return {**out, "seconds": time.perf_counter() - t0}


def _task_seconds(outcome: dict[str, Any] | BaseException) -> float:
    if isinstance(outcome, BaseException):
        return float(getattr(outcome, "sysid_seconds", 0.0) or 0.0)
    return float(outcome.get("seconds", 0.0))


def name_list(names: Sequence[str], shown: int = 5) -> str:
    """``a, b, c, d, e and 3 more``: groups named in one line."""
    more = len(names) - shown
    return ", ".join(names[:shown]) + (f" and {more} more" if more > 0 else "")


def model_path(out_dir: Path, group: str) -> Path:
    """Where a group's model goes: ``out_dir/GROUP.h5``."""
    return out_dir / f"{group}.h5"


def check_model_paths(groups: dict[str, list[Path]], *, out_dir: Path,
                      rows: Sequence[BatchRow] = ()) -> None:
    """:class:`ParameterError` when a group's model would be written over a session the batch
    reads (``--group-by session`` names a group after its file: ``--out`` the sessions' own
    folder replaced every recorded flight with its model)."""
    inputs = [Path(p) for paths in groups.values() for p in paths]
    inputs += [Path(p) for row in rows for p in row.sessions]
    for name in groups:
        target = model_path(out_dir, name)
        if any(_same_file(target, src) for src in inputs):
            raise ParameterError(f"--out {out_dir}: the model of group {name!r} ({target.name}) "
                                 f"would replace the session {target}, an input of this batch; "
                                 "choose another folder for the models")


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and a.samefile(b)
    except OSError:
        return False


def run_batch(
    groups: dict[str, list[Path]], *, out_dir: Path,
    load: Callable[[list[Path]], list[list[IOData]]], method: Method, options: Options,
    grid: dict[str, list[int]], workers: int = 1, client: Any | None = None,
    rows: list[BatchRow] | None = None, progress: Callable[[int, int], None] | None = None,
    choose_focus: bool = False, choose_feedthrough: bool | Literal["open-loop"] = False,
    choose_method: bool = False, finished: dict[str, BatchRow] | None = None,
    group_progress: Callable[[str, int, int], None] | None = None,
) -> list[BatchRow]:
    """Identify every group, saving ``out_dir/GROUP.h5`` and rewriting the summary as each
    group ends (``rows`` holds rows already known, e.g. unreadable sessions). Locally the
    groups run one after another, each sweep on ``workers`` processes; with ``client`` every
    group is one task on the Dask cluster (its records sent with it).

    The rows are the same either way: ``rows``, then the groups in the order of ``groups``
    (the summary lists the finished ones in that order while the batch runs), and
    ``seconds`` is the group's own time: loading its sessions, identifying (measured where
    that runs, so without the time a task waited on the cluster) and saving its model.

    A fault of the cluster (:class:`~sysid.errors.ClusterError`: the scheduler lost, no
    workers left) ends the batch with one line that counts the finished groups of ``groups``
    (kept in the summary with ``rows``, which are not counted: they never ran) and names the
    groups not run; those are no rows, they did not fail. ``finished`` holds rows of groups
    kept from an earlier run (:func:`sysid.batch_resume.resumable`): those groups are not run
    again. ``group_progress(group, models done, models)`` follows each group's selection when
    the groups run here (not on a cluster)."""
    known = list(rows or [])
    names = list(groups)
    done_rows = {n: r for n, r in (finished or {}).items() if n in groups}
    total, done = len(groups) - len(done_rows), 0
    check_model_paths(groups, out_dir=out_dir, rows=known)
    make_out_folder(out_dir)

    def in_order() -> list[BatchRow]:
        return known + [done_rows[n] for n in names if n in done_rows]

    write_summary(in_order(), out_dir)
    pending: dict[str, tuple[BatchRow, float]] = {}  # submitted: (row, seconds to load it)
    task_options = {"method": method, "options": options, "grid": grid,
                    "choose_focus": choose_focus, "choose_feedthrough": choose_feedthrough,
                    "choose_method": choose_method}

    def finish(row: BatchRow, seconds: float, outcome: dict[str, Any] | BaseException) -> None:
        nonlocal done
        t0 = time.perf_counter()
        if not isinstance(outcome, BaseException):
            path = model_path(out_dir, row.group)
            try:
                outcome["model"].save(path)
            except Exception as exc:  # e.g. the disk is full: this group fails, the rest go on
                outcome = exc
        if isinstance(outcome, BaseException):
            row.error = first_line(outcome)
        else:
            row.past, row.future, row.order = outcome["past"], outcome["future"], outcome["order"]
            row.focus, row.method = outcome["focus"], outcome["method"]
            row.poles = list(np.sort_complex(outcome["model"].poles()))
            row.fit, row.score, row.stable = outcome["fit"], outcome["score"], outcome["stable"]
            row.outputs, row.warnings = outcome["outputs"], outcome["warnings"]
            row.model = str(path)
        row.seconds = seconds + time.perf_counter() - t0
        done_rows[row.group] = row
        write_summary(in_order(), out_dir)
        done += 1
        log.info("group %s: %s", row.group, row.error or f"order {row.order}")
        if progress is not None:
            progress(done, total)

    futures: dict[Any, str] = {}
    try:
        for name, paths in groups.items():
            if name in done_rows:
                continue
            row, t0 = BatchRow(group=name, sessions=[str(p) for p in paths]), time.perf_counter()
            try:
                data = load(paths)
                row.flights = sum(1 for g in data if g)  # sessions read, not experiments
                if client is None:
                    report = None if group_progress is None else (
                        lambda d, t, name=name: group_progress(name, d, t))
                    outcome: dict[str, Any] | BaseException = _group_task(
                        data, workers=workers, progress=report, **task_options)
                else:
                    fut = client.submit(_group_task, data, pure=False, **task_options)
                    futures[fut] = name
                    pending[name] = (row, time.perf_counter() - t0)
                    continue
            except Exception as exc:  # a failed group is a row, never the end of the batch
                _log_unexpected(name, exc)
                outcome = exc
            finish(row, time.perf_counter() - t0, outcome)
        if futures:
            from sysid.cluster import WorkerWatch, completed, task_result

            workers = WorkerWatch(client)  # one no-worker wait for the whole run
            for fut in completed(client, list(futures), workers=workers):
                try:
                    result = task_result(client, fut, workers=workers)
                except ClusterError:  # the scheduler lost while fetching: no group's fault
                    raise
                except Exception as exc:  # also a worker lost on the cluster (KilledWorker)
                    _log_unexpected(futures[fut], exc)
                    result = exc
                row, load_s = pending.pop(futures[fut])
                finish(row, load_s + _task_seconds(result), result)
    except ClusterError as exc:
        from sysid.cluster import cancel_quietly

        cancel_quietly(client, futures, exc)
        not_run = [n for n in names if n in pending]
        kept = len(done_rows)  # the groups that ended, not the rows given (unreadable sessions)
        raise type(exc)(f"{exc}; {kept} finished group(s) kept in "
                        f"{out_dir / 'summary.json'} and {out_dir / 'summary.csv'}; "
                        f"{len(not_run)} group(s) not run: {name_list(not_run)}") from None
    except BaseException as exc:
        if futures:
            from sysid.cluster import cancel_quietly

            cancel_quietly(client, futures, exc)
        raise
    return in_order()
