"""``groundstation sim --firmware``: serve SITL firmware vehicles until Ctrl-C, SIGTERM or the
parent's death, and never leave a firmware process behind."""

from __future__ import annotations

import contextlib
import os
import signal
import time
from collections.abc import Iterator

import click

from groundstation.sim.sitl import FirmwareError, SitlServer

__all__ = ["serve_firmware"]


class _Stop(Exception):
    """Raised in the main thread by SIGTERM/SIGHUP: leave the serve loop and clean up."""


@contextlib.contextmanager
def _terminate_as_exception() -> Iterator[None]:
    def raise_stop(signum: int, _frame: object) -> None:
        raise _Stop(signal.Signals(signum).name)

    old = {s: signal.signal(s, raise_stop) for s in (signal.SIGTERM, signal.SIGHUP)}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, handler)


def serve_firmware(*, host: str, port: int, vehicles: int, seed: int, duration_s: float,
                   allow_remote: bool = False) -> None:
    """Start ``vehicles`` firmware instances, print their URIs once calibrated, serve.

    Each vehicle serves one client at a time; a ``host`` other machines reach needs
    ``allow_remote`` (:class:`~groundstation.errors.LinkError` otherwise, before anything starts).

    Ends on Ctrl-C, SIGTERM, SIGHUP, when the parent process dies (checked every 0.2 s; the
    firmware processes die with this one through ``PR_SET_PDEATHSIG``), after ``duration_s``
    (0: never), or with :class:`FirmwareError` when a firmware process exits.
    """
    parent = os.getppid()
    with _terminate_as_exception():
        try:
            with SitlServer(host=host, port=port, vehicles=vehicles, seed=seed,
                            allow_remote=allow_remote) as server:
                server.wait_ready()
                for v in server.vehicles:
                    click.echo(f"Crazyflie firmware (SITL, pid {v.proc.pid}) on {v.uri}")
                click.echo("Ctrl-C to stop", nl=True)
                start = time.monotonic()
                while not duration_s or time.monotonic() - start < duration_s:
                    time.sleep(0.2)
                    dead = server.dead()
                    if dead:
                        raise FirmwareError(f"the SITL firmware of {dead[0].uri} exited "
                                            f"({dead[0]._exit_text()})")
                    if os.getppid() != parent:
                        click.echo("parent process gone: stopping", err=True)
                        break
        except (KeyboardInterrupt, _Stop):
            click.echo("stopping")
