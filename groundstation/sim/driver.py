"""The ``sim://`` link: a cflib link driver in front of a simulation (:mod:`.simulator`).

:func:`install` puts :class:`SimDriver` at the front of ``cflib.crtp.CLASSES`` (no patching of
cflib); cflib then opens ``sim://N?speed=...`` like any other URI (options in
:mod:`groundstation.sim.uri`). Closing the link on purpose powers the simulation off.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import cflib.crtp
from cflib.crtp.crtpdriver import CRTPDriver
from cflib.crtp.crtpstack import CRTPPacket
from cflib.crtp.exceptions import WrongUriType

from groundstation.sim.registry import running_addresses, simulator_for_uri
from groundstation.sim.simulator import Simulator
from groundstation.sim.uri import parse_uri

__all__ = ["SimDriver", "install"]

_QUALITY_EVERY = 100  # received packets per link-quality report


class SimDriver(CRTPDriver):
    """cflib link driver for ``sim://`` URIs (see the module docstring for the options)."""

    def __init__(self) -> None:
        super().__init__()
        self.needs_resending = False  # replies are never lost in process
        self._sim: Simulator | None = None
        self._token = 0
        self._lost = False
        self._error_cb: Callable[[str], None] | None = None
        self._stats_cb: Callable[[dict], None] | None = None
        self._received = 0
        self._dropped_at = 0

    def connect(self, uri, radio_link_statistics_callback, link_error_callback) -> None:
        if not str(uri).startswith("sim://"):
            raise WrongUriType("Not a sim:// URI")
        opts = parse_uri(uri)
        self._sim = simulator_for_uri(uri)
        self._error_cb = link_error_callback
        self._stats_cb = radio_link_statistics_callback
        self._token = self._sim.attach(faults=opts.faults, on_lost=self._link_lost)
        self._dropped_at = self._sim.dropped_packets

    def _link_lost(self, message: str) -> None:
        self._lost = True
        if self._error_cb is not None:
            self._error_cb(message)

    def send_packet(self, pk) -> None:
        if self._sim is not None:
            self._sim.submit(header=pk.header, data=bytes(pk.data), token=self._token)

    def receive_packet(self, wait=0):
        sim = self._sim
        if sim is None:
            if wait:
                time.sleep(min(max(wait, 0), 0.1))
            return None
        packet = sim.receive(token=self._token, wait=wait)
        if packet is None:
            return None
        self._received += 1
        if self._received % _QUALITY_EVERY == 0:
            self._report_quality(sim)
        return CRTPPacket(packet[0], packet[1])

    def _report_quality(self, sim: Simulator) -> None:
        """Link quality as the radio driver reports it: the share of packets that got through
        (here: log packets not lost to the ``drop`` fault) over the last window, in %."""
        dropped = sim.dropped_packets - self._dropped_at
        self._dropped_at = sim.dropped_packets
        if self._stats_cb is not None:
            quality = 100.0 * _QUALITY_EVERY / (_QUALITY_EVERY + dropped)
            self._stats_cb({"link_quality": quality})

    def get_status(self) -> str:
        return "simulated Crazyflie" if self._sim is None else f"simulated, {self._sim.speed}x"

    def get_name(self) -> str:
        return "sim"

    def scan_interface(self, address=None) -> list:
        return [[f"sim://{a}", ""] for a in running_addresses()]

    def enum(self) -> list:
        return self.scan_interface()

    def get_help(self) -> str:
        return "sim://N?speed=20&seed=3&drop=0.05&latency_ms=20&cut_at=12.5"

    def close(self) -> None:
        sim, self._sim, self._error_cb = self._sim, None, None
        if sim is None:
            return
        sim.detach(token=self._token)
        if not self._lost:  # closed on purpose: switch the vehicle off
            sim.close()


def install() -> None:
    """Make cflib open ``sim://`` URIs (idempotent; no patching of cflib)."""
    if not cflib.crtp.CLASSES:
        cflib.crtp.init_drivers()
    if SimDriver not in cflib.crtp.CLASSES:
        cflib.crtp.CLASSES.insert(0, SimDriver)
