"""The ``groundstation`` command line.

Each sub-command lives in its own module under :mod:`groundstation.commands`; this module only
assembles the group and turns user mistakes into one-line errors with exit code 2.
"""

from __future__ import annotations

import importlib
import logging
import signal

import click

from cfcommon.cli import OneLineErrorGroup, setup_logging
from groundstation import __version__
from groundstation.errors import GroundStationError, SessionError

__all__ = ["main"]


_COMMANDS: dict[str, tuple[str, str]] = {
    # name: (module in groundstation.commands, one-line help shown by --help without importing it)
    "fly": ("fly", "Fly a flight plan and record it to a session file."),
    "plan": ("plan", "Validate and look at flight plans (flightplans/*.toml)."),
    "scan": ("scan", "List Crazyradios and Crazyflies."),
    "info": ("info", "Show what session files hold: streams, rates, dropped packets, phases."),
    "replay": ("replay", "Show a recorded session in Rerun, or write it to .rrd."),
    "export": ("export", "Write a session as CSV files, a MATLAB .mat or Parquet."),
    "import": ("importer",
               'Import uSD-card deck logs and cfclient "log to file" CSVs as session files.'),
    "sim": ("sim", "Serve simulated Crazyflie 2.1s over UDP, in real time, until Ctrl-C."),
    "demo": ("demo", "Fly two PRBS flights on the simulator, identify a model from one, "
                     "validate on the other."),
}
"""Sub-commands, loaded on use: ``--help`` need not import cflib, scipy and rerun."""


class _Group(OneLineErrorGroup):
    """Lazily loaded sub-commands; user errors print one line and exit 2, never a traceback."""

    user_errors = (GroundStationError, SessionError)

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(_COMMANDS)

    def get_command(self, ctx: click.Context, cmd_name: str) -> click.Command | None:
        if cmd_name not in _COMMANDS:
            return None
        module = importlib.import_module(f"groundstation.commands.{_COMMANDS[cmd_name][0]}")
        return module.command

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        with formatter.section("Commands"):
            formatter.write_dl([(name, helptext) for name, (_, helptext) in _COMMANDS.items()])


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
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        # A script's background job starts with SIGINT ignored; a flight honours it once
        # flying (groundstation.flight.realtime), so it must not be lost while connecting
        # either: an operator's interrupt before take-off would then let the whole plan fly.
        signal.signal(signal.SIGINT, signal.default_int_handler)
    setup_logging(verbose=verbose)
    # cflib logs link failures with full tracebacks; we report them in one line (see -vv).
    logging.getLogger("cflib").setLevel(logging.DEBUG if verbose >= 2 else logging.CRITICAL)


