"""Flat out (lock-step) a commander packet takes effect a per-flight delay after it is handled,
as over a radio, whose packets land at no fixed phase of the firmware's 50 Hz log clock: with
none, every setpoint of every lock-step flight landed 10-11 ms after a log sample, which flattered
the models identified from them (docs/simulator.md, "Radio phase in lock-step")."""

from __future__ import annotations

import math
import struct
import time

import pytest

from groundstation.sim.simulator import Simulator
from groundstation.sim.uri import Faults

RPYT = 0x30  # port 3 (commander), channel 0: roll, pitch, yaw rate, thrust
STOP = 0x70  # port 7 (generic commander), channel 0, type 0: the stop setpoint


def _wait(cond, what: str) -> None:
    deadline = time.monotonic() + 10.0  # a condition, never a duration
    while not cond():
        assert time.monotonic() < deadline, what
        time.sleep(0.005)


def _setpoint_delays_ms(seed: int, n: int = 6) -> list[int]:
    """Firmware ms from the held tick a setpoint is sent at to the one it takes effect at."""
    sim = Simulator(speed=math.inf, seed=seed)
    try:
        token, clock = sim.attach(), sim.clock
        t = clock.now()
        delays = []
        for k in range(n):
            clock.sleep_until(t + 0.1 * (k + 1))  # a scheduler's 10 Hz tick: time held there
            sent_ms = sim.vehicle.firmware_ms
            sim.submit(header=RPYT, data=struct.pack("<fffH", 0.0, 0.0, 0.0, 0), token=token)
            clock.sleep_until(t + 0.1 * (k + 1) + 0.05)
            delays.append(sim.vehicle.commander.timestamp_ms - sent_ms)
        return delays
    finally:
        sim.close()


def test_setpoints_land_at_a_seeded_phase_per_flight():
    flights = {seed: _setpoint_delays_ms(seed) for seed in range(5)}
    for seed, delays in flights.items():
        assert all(0 <= d <= 20 for d in delays), (seed, delays)
        assert max(delays) - min(delays) <= 2, (seed, delays)  # +-1 ms a packet
    assert _setpoint_delays_ms(2) == flights[2]  # the seed decides: lock-step stays repeatable
    assert len({round(sum(d) / len(d)) for d in flights.values()}) >= 3, flights


def test_a_stop_sent_just_before_the_link_closes_lands():
    """The runner sends the stop setpoint and closes the link at once: what the link sent before
    it closed lands, delayed or still unhandled, and in order."""
    sim = Simulator(speed=math.inf, seed=7)
    try:
        token = sim.attach()
        sim.submit(header=RPYT, data=struct.pack("<fffH", 0.0, 0.0, 0.0, 30000), token=token)
        sim.submit(header=STOP, data=b"\x00", token=token)
        sim.detach(token=token)
        _wait(lambda: sim.vehicle.stop_count == 1, "the stop setpoint never reached the vehicle")
        assert sim.vehicle.commander.sp.thrust == 0  # the stop came after the setpoint
    finally:
        sim.close()


@pytest.mark.parametrize("speed", [math.inf, 20.0])
def test_a_stop_sent_just_before_the_vehicle_is_switched_off_lands(speed):
    """``sim://``'s driver, closing on purpose, detaches and powers the vehicle off at once."""
    sim = Simulator(speed=speed, seed=3)
    token = sim.attach()
    sim.submit(header=STOP, data=b"\x00", token=token)
    sim.detach(token=token)
    sim.close()
    assert sim.vehicle.stop_count == 1


@pytest.mark.parametrize("seed", range(4))
def test_a_stop_handled_before_a_cut_lands_after_its_radio_delay(seed):
    sim = Simulator(speed=math.inf, seed=seed)
    try:
        token, clock = sim.attach(faults=Faults(cut_at=0.100)), sim.clock
        clock.sleep_until(0.090)  # held at 95 ms (the lead): handled 5 ms before the cut
        sim.submit(header=STOP, data=b"\x00", token=token)
        clock.sleep_until(0.2)
        assert sim.vehicle.stop_count == 1
    finally:
        sim.close()


def test_a_late_packet_of_a_detached_link_is_not_taken_for_the_next_one():
    sim = Simulator(speed=math.inf, seed=1)
    try:
        first = sim.attach()
        sim.detach(token=first)
        second = sim.attach()
        assert second != first
        clock = sim.clock
        clock.sleep_until(clock.now() + 0.05)  # the first link's marker is handled
        sim.submit(header=STOP, data=b"\x00", token=first)  # late, from the old link
        clock.sleep_until(clock.now() + 0.05)
        assert sim.vehicle.stop_count == 0
    finally:
        sim.close()
