"""``groundstation import PATH... --out DIR``: uSD-card logs and cfclient CSVs to sessions."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import click

from groundstation.errors import SessionError
from groundstation.importers.to_session import csv_to_session, usd_to_session
from groundstation.session import open_session

__all__ = ["command", "plan_imports"]

_USD_MAGIC = b"\xbc"


def _kind(path: Path) -> str:
    """``usd`` or ``csv`` from the first bytes; one-line error for anything else."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(9)
    except OSError as exc:
        raise SessionError(f"{path}: cannot read ({exc.strerror}); check the path") from None
    if head[:1] == _USD_MAGIC:
        return "usd"
    if head.startswith(b"Timestamp"):
        return "csv"
    raise SessionError(
        f"{path}: neither a uSD-card deck log (0xBC first byte) nor a cfclient CSV "
        "('Timestamp,...' header); pass those only"
    )


def plan_imports(paths: list[Path]) -> list[tuple[str, list[Path], str]]:
    """What to write: ``(kind, source files, output stem)`` per session.

    Each uSD log is one session; the CSVs of one folder (one cfclient logging session) are one
    session named after the folder; a folder argument stands for the CSVs in it.
    """
    jobs: list[tuple[str, list[Path], str]] = []
    csv_groups: dict[Path, list[Path]] = defaultdict(list)
    for p in paths:
        if not p.exists():
            raise SessionError(f"{p}: no such file or folder")
        if p.is_dir():
            found = sorted(p.glob("*.csv"))
            if not found:
                raise SessionError(f"{p}: folder holds no .csv files; pass cfclient CSVs")
            csv_groups[p.resolve()].extend(found)
        elif _kind(p) == "usd":
            jobs.append(("usd", [p], p.stem))
        else:
            csv_groups[p.resolve().parent].append(p)
    for folder, files in csv_groups.items():
        jobs.append(("csv", sorted(set(files)), folder.name or "cfclient"))
    return jobs


@click.command("import")
@click.argument("paths", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=Path),
              help="Folder for the session files (created if missing).")
@click.option("--allow-damaged", is_flag=True,
              help="Salvage the records of a uSD log whose CRC does not match.")
def command(paths: tuple[Path, ...], out_dir: Path, allow_damaged: bool) -> None:
    """Import uSD-card deck logs and cfclient "log to file" CSVs as session files.

    Each uSD log becomes one session; the CSVs of one folder (one per log block) become one
    session. Firmware times are kept; there are no setpoints, and one phase "log" covers the
    whole log (use `sysid identify --window all` or `--window log`).

    \b
    Examples:
      groundstation import /media/sd/log00 /media/sd/log01 --out sessions/
      groundstation import ~/.config/cfclient/logdata/20240101T10-00-00 --out sessions/
    """
    jobs = plan_imports(list(paths))
    for _kind_name, _files, stem in jobs:
        if (out_dir / f"{stem}.h5").exists():
            raise SessionError(f"{out_dir / (stem + '.h5')}: already exists; choose another --out")
    for kind, files, stem in jobs:
        out = out_dir / f"{stem}.h5"
        if kind == "usd":
            usd_to_session(source=files[0], out=out, allow_damaged=allow_damaged)
        else:
            csv_to_session(sources=files, out=out)
        s = open_session(out)
        rows = ", ".join(f"{n} {len(st)} rows" for n, st in s.streams.items() if st.kind == "log")
        span = sum(p.end_s - p.start_s for p in s.phases())
        click.echo(f"{out}: {rows}, {span:.2f} s "
                   f"(from {len(files)} {kind} file{'s' if len(files) > 1 else ''})")
