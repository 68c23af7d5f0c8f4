"""The emulated-radio backend of the flight tests: an emulated Crazyradio PA on an emulated USB bus
(:func:`groundstation.sim.crazyradio_usb.emulated_radio`, the documented hook) with one simulated
Crazyflie on channel 80, 2M, E7E7E7E7E7, flown by unmodified cflib over ``radio://``.

The emulated bus is one per process (the hook replaces cflib's pyusb backend), so one vehicle at a
time: :func:`start_vehicle` refuses a second before :func:`close_all`. Mirrors
``tests/sitl/backend.py``.
"""

from __future__ import annotations

import contextlib
import time

from groundstation.flight.link import install_drivers
from groundstation.sim.crazyradio_usb import EmulatedBus, RadioVehicle, emulated_radio

URI = "radio://0/80/2M/E7E7E7E7E7"
SPEED = 20

_stack: contextlib.ExitStack | None = None
_bus: EmulatedBus | None = None


def start_vehicle(*, loss: float = 0.0, bit_error_rate: float = 0.0, seed: int = 0,
                  speed: float = SPEED, safelink_capable: bool = True) -> str:
    """Put the emulated dongle (noise: ``loss`` per transmission, ``bit_error_rate`` per bit)
    and its vehicle on the bus (removed by :func:`close_all`); returns the vehicle's URI."""
    global _stack, _bus
    assert _stack is None, "the emulated radio backend has one vehicle at a time"
    install_drivers()
    stack = contextlib.ExitStack()
    _bus = stack.enter_context(emulated_radio(
        speed=speed, loss=float(loss), bit_error_rate=float(bit_error_rate), seed=int(seed),
        vehicles=[{"safelink_capable": safelink_capable}]))
    _stack = stack
    assert _bus.vehicle_for_uri(URI) is _bus.vehicles[0]
    return URI


def bus() -> EmulatedBus:
    assert _bus is not None, "no emulated radio: call start_vehicle first"
    return _bus


def vehicle(uri: str) -> RadioVehicle:
    """The simulated vehicle ``uri`` reaches on the emulated bus."""
    v = bus().vehicle_for_uri(uri)
    assert v is not None, f"no emulated vehicle answers {uri}"
    return v


def close_all() -> None:
    """Unplug the dongle, power the vehicle off and forget cflib's cached radios."""
    global _stack, _bus
    stack, _stack, _bus = _stack, None, None
    if stack is not None:
        stack.close()


def wait_for_stop(uri: str, timeout_s: float = 30.0) -> RadioVehicle:
    """The vehicle once its motors are off and it counted a stop (the stop setpoint, or its
    supervisor's watchdog). Wall-clock deadline only as a guard: at speed 20 this takes well under
    a second on an idle host."""
    v = vehicle(uri)
    sim = v.sim.vehicle
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if sim.stop_count >= 1 and not any(sim.motors_pwm):
            return v
        time.sleep(0.01)
    raise AssertionError(f"emulated-radio vehicle not stopped: motors {sim.motors_pwm}, "
                         f"stop_count {sim.stop_count}")
