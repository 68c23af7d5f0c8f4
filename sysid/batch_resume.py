"""Finishing an interrupted batch (``sysid batch --resume``).

A batch writes ``batch.json`` into its folder before it runs: its configuration (grouping,
method, horizons, order, focus, stability, session options, the sysid version), the folder it
was started from, and each input session's resolved path, size and modification time.
:func:`resumable` reads it back with ``summary.json`` and gives the rows a resumed batch keeps:
those of groups that were identified, whose sessions are the same files, unchanged, and whose
model file is still the one the row describes (its poles). The resumed batch runs every other
group: the ones an interruption left, a failed one (a full disk, a lost worker may not fail
again), a deleted model.

Anything else is refused in one line, so that ``--resume`` never mixes two batches in one
summary: other settings (naming them), a group whose sessions changed or whose model file is
not the row's, a group of the earlier batch that this one does not identify (its row would be
dropped while its model stays). ``--force`` runs the batch again from the start.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from sysid.batch import BatchRow, make_out_folder, model_path, name_list
from sysid.errors import ParameterError, first_line
from sysid.model_io import load

__all__ = ["CONFIG_FILE", "resumable", "write_config"]

CONFIG_FILE = "batch.json"
_FORMAT = "cf-sysid-batch"
_AGAIN = "pass --force to run the batch again"


def _fingerprint(path: Path) -> list[int] | None:
    """``[size, mtime_ns]`` of a file, None when it cannot be read."""
    try:
        st = path.stat()
    except OSError:
        return None
    return [st.st_size, st.st_mtime_ns]


def write_config(out_dir: Path, config: Mapping[str, Any], *, sessions: Sequence[Path]) -> None:
    """``out_dir/batch.json`` (module docstring; the folder is made if missing)."""
    make_out_folder(out_dir)
    files = {str(p.resolve()): _fingerprint(p) for p in map(Path, sessions)}
    tmp = out_dir / f".{CONFIG_FILE}.tmp"
    tmp.write_text(json.dumps({"format": _FORMAT, "version": 1, "configuration": dict(config),
                               "cwd": os.getcwd(), "sessions": files}, indent=1))
    tmp.replace(out_dir / CONFIG_FILE)


def _read(out_dir: Path) -> tuple[dict[str, Any], list[BatchRow]]:
    try:
        saved = json.loads((out_dir / CONFIG_FILE).read_text())
        rows = [BatchRow.from_record(r) for r in json.loads((out_dir / "summary.json").read_text())]
        if saved.get("format") != _FORMAT or not isinstance(saved["configuration"], dict) \
                or not isinstance(saved["sessions"], dict) or not isinstance(saved["cwd"], str):
            raise ValueError(f"{CONFIG_FILE} is not a batch configuration")
    except FileNotFoundError as exc:
        name = Path(exc.filename or "").name
        advice = ("run without --resume" if name == "summary.json" else
                  f"the batch was started by an older sysid or not at all; {_AGAIN}")
        raise ParameterError(f"--resume: {out_dir} holds no batch to resume ({name} missing); "
                             f"{advice}") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RecursionError) as exc:
        raise ParameterError(f"--resume: {out_dir}: its {CONFIG_FILE} or summary.json cannot be "
                             f"read ({first_line(exc)}); {_AGAIN}") from None
    return saved, rows


def _option(key: str) -> str:
    """The command-line option a configuration key comes from (``windows``: ``--window``)."""
    return "--window" if key == "windows" else "--" + key.replace("_", "-")


def _same_model(path: Path, row: BatchRow) -> bool:
    """Whether ``path`` holds the model ``row`` describes (its poles)."""
    try:
        poles = np.sort_complex(load(path).poles())
    except Exception:  # unreadable, or not a model file: not the row's
        return False
    return poles.shape == (len(row.poles),) and bool(
        np.allclose(poles, np.sort_complex(np.array(row.poles)), rtol=1e-9, atol=1e-12))


def resumable(out_dir: Path, groups: Mapping[str, Sequence[Path]], config: Mapping[str, Any]
              ) -> dict[str, BatchRow]:
    """The rows of the earlier batch in ``out_dir`` that the resumed one keeps, by group, with
    their sessions as this command names them (module docstring); :class:`ParameterError`
    otherwise."""
    saved, rows = _read(out_dir)
    before, now = saved["configuration"], json.loads(json.dumps(dict(config)))
    differ = sorted(k for k in {*before, *now} if before.get(k) != now.get(k))
    if differ:
        raise ParameterError(
            f"--resume: the batch in {out_dir} ran with other settings ("
            + ", ".join(f"{_option(k)} {before.get(k)!r} then, {now.get(k)!r} now"
                        for k in differ)
            + "); give the same options, or --force to run it again")
    then_cwd, files = Path(saved["cwd"]), saved["sessions"]
    ran = [r for r in rows if r.error is None]
    gone = [r.group for r in ran if r.group not in groups]
    if gone:
        raise ParameterError(f"--resume: the batch in {out_dir} also has group(s) "
                             f"{name_list(gone)}, which this command does not identify (not "
                             "given, or unreadable now); give the same sessions, or "
                             f"{_AGAIN}")
    kept, changed = {}, []
    for row in ran:
        paths = [Path(p) for p in groups[row.group]]
        same = [str((then_cwd / s).resolve()) for s in row.sessions] == [
            str(p.resolve()) for p in paths]
        if not same or any(files.get(str(p.resolve())) != _fingerprint(p) for p in paths):
            changed.append(f"{row.group} (its sessions)")
            continue
        target = model_path(out_dir, row.group)
        if not target.exists():
            continue  # deleted: made again
        if not _same_model(target, row):
            changed.append(f"{row.group} ({target.name})")
            continue
        row.sessions, row.model = [str(p) for p in paths], str(target)
        kept[row.group] = row
    if changed:
        raise ParameterError(f"--resume: changed since the batch in {out_dir} ran: "
                             f"{name_list(changed)}; {_AGAIN}")
    return kept
