"""``groundstation sim``: simulated Crazyflies over UDP for cflib scripts and cfclient."""

from __future__ import annotations

import logging
import time

import click

from cfcommon.cli import FiniteFloat
from groundstation.sim.udp import UdpServer

__all__ = ["command"]

logger = logging.getLogger(__name__)


@click.command("sim")
@click.option("--port", default=19850, show_default=True, type=int,
              help="UDP port of the first vehicle; vehicle i listens on PORT + i.")
@click.option("--count", "--vehicles", "count", default=1, show_default=True,
              type=click.IntRange(1, 10),
              help="Number of vehicles (cflib scans ports 19850-19859).")
@click.option("--firmware", is_flag=True,
              help="Run the real Crazyflie firmware (SITL, built by `make sitl`) with the "
                   "simulator's physics instead of the emulated firmware; real time only.")
@click.option("--host", default="127.0.0.1", show_default=True,
              help="Address to bind; another address than 127.0.0.1 (0.0.0.0: every "
                   "interface) needs --allow-remote.")
@click.option("--allow-remote", is_flag=True,
              help="Allow a --host other machines reach: anyone there can fly the vehicle.")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(0),
              help="Random seed of the first vehicle (vehicle i uses SEED + i).")
@click.option("--duration", default=0.0, type=FiniteFloat(min=0.0), hidden=True,
              help="Stop after this many seconds (0: run until Ctrl-C).")
def command(port: int, count: int, host: str, allow_remote: bool, seed: int,
            duration: float, firmware: bool) -> None:
    """Serve simulated Crazyflie 2.1s over UDP, in real time, until Ctrl-C.

    Each vehicle speaks CRTP like real firmware (log and param TOCs, log blocks, commander,
    supervisor watchdog) with simulated physics. Any cflib >= 0.1.32 program or the Crazyflie
    client connects to udp://HOST:PORT; a client that goes silent in flight leaves the vehicle
    to its watchdog, as a real one. Each vehicle serves one client at a time (the first to
    send, until it goes silent for 1 s); datagrams from others are ignored and counted.

    \b
    Examples:
      groundstation sim --port 19850 --count 2
      groundstation sim --firmware  (the real firmware: make sitl first)
      cfclient                      (Scan finds udp://127.0.0.1:19850, then Connect)
      python -c "import cflib.crtp; from cflib.crazyflie import Crazyflie; \\
        from cflib.crazyflie.syncCrazyflie import SyncCrazyflie; cflib.crtp.init_drivers(); \\
        scf = SyncCrazyflie('udp://127.0.0.1:19850', cf=Crazyflie()); scf.open_link(); \\
        print(scf.cf.param.get_value('pm.lowVoltage')); scf.close_link()"
    """
    # The host rule (groundstation.sim.client_policy.check_host) is the servers': a host other
    # machines reach without --allow-remote is a one-line error, with it a logged warning.
    if firmware:
        from groundstation.sim.sitl_serve import serve_firmware

        serve_firmware(host=host, port=port, vehicles=count, seed=seed, duration_s=duration,
                       allow_remote=allow_remote)
        return
    with UdpServer(host=host, port=port, count=count, seed=seed,
                   allow_remote=allow_remote) as server:
        for uri in server.uris:
            click.echo(f"simulated Crazyflie on {uri}")
        click.echo("Ctrl-C to stop")
        start = time.monotonic()
        try:
            while not duration or time.monotonic() - start < duration:
                time.sleep(0.2)
        except KeyboardInterrupt:
            click.echo("stopping")
