"""The ``sysid`` command line (identification from session files)."""

from __future__ import annotations

import logging

import click

__all__ = ["main"]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="cf-sysid", prog_name="sysid")
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
def main(verbose: int) -> None:
    """Closed-loop subspace identification (IEM, PO-MOESP) of flight sessions."""
    level = logging.WARNING - 10 * min(verbose, 2)
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s")
