"""Fixtures for the emulated Crazyradio: an emulated USB bus with one Crazyradio PA and one
simulated Crazyflie on channel 80, 2M, E7E7E7E7E7 (20x real time), removed after each test."""

from __future__ import annotations

import pytest

from groundstation.flight.link import install_drivers
from groundstation.sim.crazyradio_usb import emulated_radio

from .backend import SPEED, URI

__all__ = ["SPEED", "URI", "bus"]


@pytest.fixture
def bus():
    install_drivers()
    with emulated_radio(speed=SPEED) as made:
        yield made
