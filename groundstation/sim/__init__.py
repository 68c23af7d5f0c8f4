"""A simulated Crazyflie 2.1 that speaks real CRTP.

In process, through cflib: call :func:`install` once, then open ``sim://0?speed=20`` like any
other URI (options in :mod:`groundstation.sim.uri`); :func:`instance` reaches the simulation
behind a URI (its ``.vehicle``, fault methods and clock). Over UDP: :class:`UdpServer` (the
``groundstation sim`` command) serves the cflib >= 0.1.32 UDP protocol on ``udp://127.0.0.1:19850``.
Through a Crazyradio: :func:`emulated_radio` puts an emulated dongle on an emulated USB bus
(:mod:`groundstation.sim.crazyradio_usb`) so ``radio://`` runs through unmodified cflib.
See ``docs/simulator.md``.
"""

from groundstation.sim.clock import SimClock
from groundstation.sim.crazyradio_usb import emulated_radio
from groundstation.sim.crtp import CrtpPeer
from groundstation.sim.driver import SimDriver, install
from groundstation.sim.registry import close_all, instance, simulator_for_uri
from groundstation.sim.simulator import Simulator
from groundstation.sim.udp import UdpServer
from groundstation.sim.uri import Faults, parse_uri
from groundstation.sim.vehicle import SimVehicle

__all__ = [
    "CrtpPeer",
    "Faults",
    "SimClock",
    "SimDriver",
    "SimVehicle",
    "Simulator",
    "UdpServer",
    "close_all",
    "emulated_radio",
    "install",
    "instance",
    "parse_uri",
    "simulator_for_uri",
]
