"""Fixtures for the simulated Crazyflie's protocol tests: a fresh ``sim://`` URI per test, every
simulation powered off afterwards, and no simulator thread left behind."""

from __future__ import annotations

import itertools
import threading
import time

import pytest

import groundstation.sim as gsim

_counter = itertools.count(100)


def _sim_threads() -> list[str]:
    return [t.name for t in threading.enumerate() if t.name.startswith("sim-")]


@pytest.fixture
def sim_uri() -> str:
    """A URI no other test uses, at 20x real time; the driver is installed."""
    gsim.install()
    yield f"sim://{next(_counter)}?speed=20"
    gsim.close_all()
    deadline = time.monotonic() + 3.0
    while _sim_threads() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert not _sim_threads(), f"simulator threads left running: {_sim_threads()}"
