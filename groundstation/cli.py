"""The ``groundstation`` command line.

Each sub-command lives in its own module under :mod:`groundstation.commands`; this module only
assembles the group and turns user mistakes into one-line errors with exit code 2.
"""

from __future__ import annotations

import logging
import sys

import click

from groundstation import __version__
from groundstation.errors import GroundStationError

__all__ = ["main"]


class _Group(click.Group):
    """A click group whose user errors print one line and exit 2, never a traceback."""

    def invoke(self, ctx: click.Context):
        try:
            return super().invoke(ctx)
        except GroundStationError as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)
        except (FileNotFoundError, PermissionError, IsADirectoryError) as exc:
            click.echo(f"error: {exc.strerror}: {exc.filename}", err=True)
            sys.exit(2)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="groundstation")
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
def main(verbose: int) -> None:
    """Crazyflie flight-test ground station.

    \b
    Fly declarative flight plans over a Crazyradio (or the simulator), record every flight
    to a crash-safe HDF5 session file, and look at it live or later in Rerun.

    \b
    Examples:
      groundstation info sessions/prbs-3axis-20261122T100000Z.h5
      groundstation demo
    """
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
    # cflib logs link failures with full tracebacks; we report them in one line (see -vv).
    logging.getLogger("cflib").setLevel(logging.DEBUG if verbose >= 2 else logging.CRITICAL)


def _register() -> None:
    from groundstation.commands import demo, fly, importer, info, plan, replay, scan, sim

    for module in (info, demo, sim, plan, importer, fly, scan, replay):
        main.add_command(module.command)


_register()
