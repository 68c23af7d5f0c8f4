"""``groundstation import PATH... --out DIR``: uSD-card logs and cfclient CSVs to sessions."""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import click

from cfsession import open_session
from cfsession.guard import flight_log_kind
from groundstation.errors import SessionError
from groundstation.importers.to_session import OutputFolderError, csv_to_session, usd_to_session
from groundstation.recorder import check_folder

__all__ = ["ImportJob", "command", "plan_imports"]

Kind = Literal["usd", "csv"]


@dataclass(frozen=True)
class ImportJob:
    """One session to write: its ``kind``, source ``files`` and output file ``stem``."""

    kind: Kind
    files: tuple[Path, ...]
    stem: str


def _kind(path: Path) -> Kind | None:
    """``usd`` or ``csv`` from the first bytes (:func:`cfsession.guard.flight_log_kind`),
    None for anything else."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(12)
    except OSError as exc:
        raise SessionError(f"{path}: cannot read ({exc.strerror}); check the path") from None
    return flight_log_kind(head)


def _is_hdf5(path: Path) -> bool:
    """The file starts with HDF5's signature (a session or a model file, not a log)."""
    from cfsession.guard import HDF5_SIGNATURE

    with open(path, "rb") as fh:
        return fh.read(len(HDF5_SIGNATURE)) == HDF5_SIGNATURE


def _entries(folder: Path) -> list[Path]:
    """The folder's entries, sorted, hidden ones (``.name``) left out."""
    try:
        return sorted(p for p in folder.iterdir() if not p.name.startswith("."))
    except OSError as exc:
        raise SessionError(f"{folder}: cannot list ({exc.strerror}); check the path") from None


def _scan(folder: Path, *, depth: int, jobs: list[ImportJob],
          csv_groups: dict[Path, list[Path]], skipped: list[Path]) -> None:
    """uSD logs and cfclient CSVs in ``folder`` and, ``depth`` levels down, its subfolders."""
    for p in _entries(folder):
        if p.is_dir():
            if depth > 0:
                _scan(p, depth=depth - 1, jobs=jobs, csv_groups=csv_groups, skipped=skipped)
            continue
        if not p.is_file():
            continue
        kind = _kind(p)
        if kind == "usd":
            jobs.append(ImportJob("usd", (p,), p.stem))
        elif kind == "csv":
            csv_groups[p.resolve().parent].append(p)
        else:
            skipped.append(p)


def plan_imports(paths: list[Path]) -> tuple[list[ImportJob], list[Path]]:
    """What to write, and the files of folder arguments that are neither kind of log.

    Each uSD log is one session named after its file; the cfclient CSVs of one folder (one per
    log block of one logging session) are one session named after the folder. A folder argument
    stands for the logs in it and in its subfolders (one level: a uSD card, cfclient's
    ``logdata/`` folder of sessions, or a mix). A file argument must be one of the two kinds.
    """
    jobs: list[ImportJob] = []
    csv_groups: dict[Path, list[Path]] = defaultdict(list)
    skipped: list[Path] = []
    for p in paths:
        if not p.exists():
            raise SessionError(f"{p}: no such file or folder")
        if p.is_dir():
            before = len(jobs) + sum(len(v) for v in csv_groups.values())
            seen = len(skipped)
            _scan(p, depth=1, jobs=jobs, csv_groups=csv_groups, skipped=skipped)
            if len(jobs) + sum(len(v) for v in csv_groups.values()) == before:
                if (p / "metadata.json").is_file() and any(p.glob("*.csv")):
                    raise SessionError(f"{p}: a 'groundstation export --to csv' folder, not a "
                                       "log to import: use the session file it was exported "
                                       "from as it is")
                found = skipped[seen:]
                sessions = sum(f.suffix.lower() == ".h5" for f in found)
                what = (f"; its {sessions} .h5 file(s) are sessions already (groundstation "
                        "info reads them)" if sessions else
                        f"; found {len(found)} other file(s): "
                        f"{', '.join(f.name for f in found[:3])}" if found else "")
                raise SessionError(f"{p}: holds no uSD-card deck logs (0xBC first byte) or "
                                   "cfclient CSVs ('Timestamp,...'), nor do its subfolders"
                                   f"{what}")
            continue
        if not p.is_file():  # opening a FIFO waits for a writer; a device reads forever
            raise SessionError(f"{p}: not a regular file (a device, FIFO or socket); pass "
                               "uSD-card deck logs, cfclient CSVs or folders of them")
        kind = _kind(p)
        if kind is None and _is_hdf5(p):
            raise SessionError(
                f"{p}: an HDF5 file (a session or a model: groundstation info reads a session "
                "as it is), not a log to import; import takes uSD-card deck logs and cfclient "
                "CSVs")
        if kind is None:
            raise SessionError(
                f"{p}: neither a uSD-card deck log (0xBC first byte) nor a cfclient CSV "
                "('Timestamp,...' header); pass those only")
        if kind == "usd":
            jobs.append(ImportJob("usd", (p,), p.stem))
        else:
            csv_groups[p.resolve().parent].append(p)
    for folder, files in csv_groups.items():
        unique = tuple(sorted(set(files), key=lambda f: f.resolve()))
        jobs.append(ImportJob("csv", unique, folder.name or "cfclient"))
    jobs = list({tuple(f.resolve() for f in j.files): j for j in jobs}.values())  # named twice
    by_stem: dict[str, ImportJob] = {}
    for j in jobs:
        if (other := by_stem.setdefault(j.stem, j)) is not j:
            raise SessionError(
                f"{other.files[0]} and {j.files[0]} would both become {j.stem}.h5; import them "
                "into different --out folders")
    return jobs, skipped


def _describe(path: Path, job: ImportJob) -> str:
    s = open_session(path)
    rows = ", ".join(f"{n} {len(st)} rows" for n, st in s.streams.items() if st.kind == "log")
    air = [p for p in s.phases() if p.kind == "airborne"]
    flown = ("airborne " + ", ".join(f"{p.start_s:.2f}-{p.end_s:.2f}" for p in air) + " s"
             if air else "no airborne segment found")
    n = len(job.files)
    return f"{path}: {rows}; {flown} (from {n} {job.kind} file{'s' if n > 1 else ''})"


@click.command("import")
@click.argument("paths", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=Path),
              help="Folder for the session files (created if missing).")
@click.option("--force", is_flag=True,
              help="Replace session files that exist (once the new one is complete).")
@click.option("--allow-damaged", is_flag=True,
              help="Import a damaged uSD log anyway: a CRC mismatch keeps every record as "
                   "read, a record cut short is dropped; the session lists the damage.")
def command(paths: tuple[Path, ...], out_dir: Path, force: bool, allow_damaged: bool) -> None:
    """Import uSD-card deck logs and cfclient "log to file" CSVs as session files.

    Each uSD log becomes one session named after it; the CSVs of one folder (one per log
    block) become one session named after the folder. A folder may hold uSD logs, CSVs,
    folders of CSVs (cfclient's logdata/) or a mix; other files in it are skipped and listed.
    Firmware times are kept. The airborne segments found from the logged thrust and height
    become phases airborne-1, airborne-2, ... (docs/session-format.md); a log without any has
    one phase "log". A failed import leaves no file behind; with several logs, the others
    are still imported, each failure (an existing session without --force, a damaged log) gets
    its line, and the exit status is 2.

    \b
    Examples:
      groundstation import /media/sd --out sessions/
      groundstation import /media/sd/log00 /media/sd/log01 --out sessions/ --force
      groundstation import ~/.config/cfclient/logdata --out sessions/
    """
    jobs, skipped = plan_imports(list(paths))
    if out_dir.exists() and not out_dir.is_dir():
        raise SessionError(f"{out_dir}: not a folder; --out takes a folder")
    check_folder(out_dir)  # created, and writable: else one line, before any work
    failed: list[str] = []
    for job in jobs:
        out = out_dir / f"{job.stem}.h5"
        if not force and (out.exists() or out.is_symlink()):  # its line; the others go on
            failed.append(f"{out}: already exists; pass --force to replace it")
            continue
        try:
            if job.kind == "usd":
                usd_to_session(source=job.files[0], out=out, allow_damaged=allow_damaged,
                               force=force)
            else:
                csv_to_session(sources=list(job.files), out=out, force=force)
        except OutputFolderError as exc:  # the next ones would fail the same way: say it once
            failed.append(str(exc))
            break
        except SessionError as exc:
            failed.append(str(exc))
            continue
        click.echo(_describe(out, job))
    if skipped:
        names = ", ".join(p.name for p in skipped[:5])
        more = f" and {len(skipped) - 5} more" if len(skipped) > 5 else ""
        click.echo(f"skipped {len(skipped)} file(s) that are neither uSD logs nor cfclient "
                   f"CSVs: {names}{more}", err=True)
    for line in failed[:-1]:
        click.echo(f"error: {line}", err=True)
    if failed:
        raise SessionError(failed[-1])
