"""Faults of the firmware in the loop (issue 15 item 6): the firmware process dies, or the physics
peer stalls, mid-flight. The ground station sees its log packets stop: link loss, the abort path,
a stop setpoint sent and recorded, a readable session. Real time, about 10 s a flight; skipped
without the firmware (``make sitl``).
"""

from __future__ import annotations

import os
import signal
import threading

import pytest

from groundstation.flight import fly_plan
from groundstation.plan import load_plan
from tests.flight.checks import check_closed_with_stop

from . import backend


@pytest.fixture
def sitl():
    v = backend.start_vehicle(seed=3)
    yield v
    backend.close_all()


def _check_link_loss(result) -> None:
    assert result.aborted and result.cause.startswith("link lost: no log packet for"), \
        result.cause
    s = check_closed_with_stop(result)
    assert any(e.source == "safety" and e.text.startswith("link lost") for e in s.events())
    assert len(s["gyro"]) > 100  # the flight up to the fault is kept


def test_firmware_killed_mid_flight_is_link_loss_with_a_readable_session(sitl, tmp_path):
    def crash(k: int) -> None:
        if k == 30:  # hovering: the firmware process dies (SIGKILL: no goodbye)
            os.kill(sitl.proc.pid, signal.SIGKILL)

    result = fly_plan(plan=load_plan("hover-check"), out=tmp_path, uri=sitl.uri,
                      tick_hook=crash)
    _check_link_loss(result)
    assert not sitl.alive


def test_stalled_physics_peer_is_link_loss_with_a_readable_session(sitl, tmp_path, monkeypatch):
    """The peer stops stepping (no more IMU packets): the real firmware steps its control loop
    per IMU packet, so it falls silent too."""
    stalled, release = threading.Event(), threading.Event()
    step = sitl.peer.step

    def stalling_step():
        if stalled.is_set():
            release.wait(30.0)
        return step()

    monkeypatch.setattr(sitl.peer, "step", stalling_step)

    def stall(k: int) -> None:
        if k == 30:
            stalled.set()

    try:
        result = fly_plan(plan=load_plan("hover-check"), out=tmp_path, uri=sitl.uri,
                          tick_hook=stall)
    finally:
        release.set()
    _check_link_loss(result)
