"""An emulated Crazyradio PA on an emulated USB bus: a pyusb backend cflib drives unmodified.

cflib reaches a Crazyradio through pyusb (``cflib/drivers/crazyradio.py``: ``usb.core.find(
idVendor=0x1915, idProduct=0x7777, backend=libusb_package.get_libusb1_backend())``, vendor
control requests, bulk EP1 OUT/IN). :class:`EmulatedUsbBackend` is a ``usb.backend.IBackend``
presenting the dongle's descriptors (bitcraze/crazyradio-firmware ``firmware/src/usbDescriptor.c``:
one configuration, interface 0 of vendor class with bulk EP 0x81 IN and 0x01 OUT of 64 bytes) and
handing requests and packets to the dongle's firmware, :class:`EmulatedCrazyradio`
(:mod:`groundstation.sim.crazyradio_firmware`), whose radio reaches :class:`RadioVehicle` s (the
simulated Crazyflie ``sim://`` uses) through the air of :mod:`groundstation.sim.radio_noise`
(``loss`` per transmission, ``bit_error_rate`` per bit: retries, CRC failures, link quality).

The only hook is the backend choice (:func:`usb_backend`): inside :func:`emulated_radio` it is
the emulated bus (``libusb_package.get_libusb1_backend``, which cflib asks, answers it too), and
``radio://`` URIs of an emulated vehicle are scheduled on its simulation clock. Everything above
pyusb is cflib's own code. See ``docs/flying.md`` for what only a real dongle shows.
"""

from __future__ import annotations

import array
import contextlib
import errno
import logging
import threading
import time
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import usb.backend
import usb.core

from groundstation.flight.clock import Clock, register_clock
from groundstation.sim.clock import SimClock
from groundstation.sim.crazyradio_firmware import (
    DESC_DEVICE,
    FIRMWARE_BCD,
    SCANN_CHANNELS,
    DataRate,
    EmulatedCrazyradio,
    RadioVehicle,
)
from groundstation.sim.radio_noise import RadioNoise, RadioStats, expected_link_quality
from groundstation.sim.simulator import Simulator

__all__ = ["DataRate", "EmulatedBus", "EmulatedCrazyradio", "EmulatedUsbBackend", "RadioNoise",
           "RadioStats", "RadioVehicle", "emulated_radio", "expected_link_quality",
           "installed_bus", "usb_backend"]

log = logging.getLogger(__name__)

_GET_DESCRIPTOR, _DESC_CONFIG, _DESC_STRING = 0x06, 2, 3
_ERROR_DELAY_S = 0.001  # a failed USB transfer still costs about a frame
_MAX_BACKLOG = 4  # downlink packets a vehicle lets wait before its simulated time holds
_IDLE_POLL_S = 0.001  # an exchange that moved no data costs a USB round trip (about 1 ms)


def _usb_error(text: str, code: int) -> usb.core.USBError:
    if code == errno.ETIMEDOUT:
        return usb.core.USBTimeoutError(text, error_code=-7, errno=code)
    return usb.core.USBError(text, error_code=-1, errno=code)


_CONFIG = SimpleNamespace(bLength=9, bDescriptorType=_DESC_CONFIG, wTotalLength=32,
                          bNumInterfaces=1, bConfigurationValue=1, iConfiguration=0,
                          bmAttributes=0x80, bMaxPower=50, extra_descriptors=[])
_INTERFACE = SimpleNamespace(bLength=9, bDescriptorType=4, bInterfaceNumber=0,
                             bAlternateSetting=0, bNumEndpoints=2, bInterfaceClass=0xFF,
                             bInterfaceSubClass=0xFF, bInterfaceProtocol=0, iInterface=0,
                             extra_descriptors=[])
_ENDPOINTS = [SimpleNamespace(bLength=7, bDescriptorType=5, bEndpointAddress=addr,
                              bmAttributes=0x02, wMaxPacketSize=64, bInterval=6, bRefresh=0,
                              bSynchAddress=0, extra_descriptors=[]) for addr in (0x81, 0x01)]
_CONFIG_BYTES = bytes([9, 2, 32, 0, 1, 1, 0, 0x80, 50, 9, 4, 0, 0, 2, 0xFF, 0xFF, 0, 0,
                       7, 5, 0x81, 2, 64, 0, 6, 7, 5, 0x01, 2, 64, 0, 6])


class EmulatedUsbBackend(usb.backend.IBackend):
    """A pyusb backend whose bus holds emulated Crazyradios (and nothing else)."""

    def __init__(self, dongles: Sequence[EmulatedCrazyradio] = ()) -> None:
        self.dongles = list(dongles)

    def enumerate_devices(self) -> Iterator[EmulatedCrazyradio]:
        return iter([d for d in self.dongles if d.plugged])

    def get_parent(self, dev: Any) -> None:
        return None

    def get_device_descriptor(self, dev: EmulatedCrazyradio) -> SimpleNamespace:
        return dev.device_descriptor()

    def get_configuration_descriptor(self, dev: Any, config: int) -> SimpleNamespace:
        if config != 0:
            raise IndexError("invalid configuration index")
        return _CONFIG

    def get_interface_descriptor(self, dev: Any, intf: int, alt: int,
                                 config: int) -> SimpleNamespace:
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError("invalid interface index")
        return _INTERFACE

    def get_endpoint_descriptor(self, dev: Any, ep: int, intf: int, alt: int,
                                config: int) -> SimpleNamespace:
        if (intf, alt, config) != (0, 0, 0) or not 0 <= ep < 2:
            raise IndexError("invalid endpoint index")
        return _ENDPOINTS[ep]

    # ------------------------------------------------------------------ handles
    @staticmethod
    def _check(dev: EmulatedCrazyradio) -> None:
        if not dev.plugged:
            time.sleep(_ERROR_DELAY_S)
            raise _usb_error("No such device (it may have been disconnected)", errno.ENODEV)

    def open_device(self, dev: EmulatedCrazyradio) -> EmulatedCrazyradio:
        self._check(dev)
        with dev.lock:
            dev.open_handles += 1
        return dev

    def close_device(self, dev_handle: EmulatedCrazyradio) -> None:
        with dev_handle.lock:
            dev_handle.open_handles = max(0, dev_handle.open_handles - 1)
            if not dev_handle.open_handles:  # the host let go: the vehicles hear nothing more
                for v in dev_handle.vehicles:
                    v.detach()

    def set_configuration(self, dev_handle: EmulatedCrazyradio, config_value: int) -> None:
        self._check(dev_handle)
        dev_handle.configuration = config_value

    def get_configuration(self, dev_handle: EmulatedCrazyradio) -> int:
        self._check(dev_handle)
        return dev_handle.configuration

    def set_interface_altsetting(self, dev_handle: Any, intf: int, altsetting: int) -> None:
        self._check(dev_handle)

    def claim_interface(self, dev_handle: Any, intf: int) -> None:
        self._check(dev_handle)

    def release_interface(self, dev_handle: Any, intf: int) -> None:
        pass

    def reset_device(self, dev_handle: EmulatedCrazyradio) -> None:
        self._check(dev_handle)

    def clear_halt(self, dev_handle: Any, ep: int) -> None:
        self._check(dev_handle)

    def is_kernel_driver_active(self, dev_handle: Any, intf: int) -> bool:
        return False

    def detach_kernel_driver(self, dev_handle: Any, intf: int) -> None:
        pass

    def attach_kernel_driver(self, dev_handle: Any, intf: int) -> None:
        pass

    # ------------------------------------------------------------------ transfers
    def bulk_write(self, dev_handle: EmulatedCrazyradio, ep: int, intf: int, data: array.array,
                   timeout: int) -> int:
        self._check(dev_handle)
        if ep != 0x01:
            raise _usb_error("Pipe error", errno.EPIPE)
        with dev_handle.lock:
            moved = dev_handle.bulk_out(bytes(data))
        if not moved:  # cflib polls with null packets: pace it like the real USB round trip
            time.sleep(_IDLE_POLL_S)
        return len(data)

    def bulk_read(self, dev_handle: EmulatedCrazyradio, ep: int, intf: int, buff: array.array,
                  timeout: int) -> int:
        self._check(dev_handle)
        if ep != 0x81:
            raise _usb_error("Pipe error", errno.EPIPE)
        with dev_handle.lock:
            data = dev_handle.bulk_in()
        if data is None:  # no packet was sent (ack disabled, carrier on): the IN never comes
            time.sleep(timeout / 1000.0 if timeout else 0.0)
            raise _usb_error("Operation timed out", errno.ETIMEDOUT)
        n = min(len(data), len(buff))
        buff[:n] = array.array("B", data[:n])
        return n

    def ctrl_transfer(self, dev_handle: EmulatedCrazyradio, bmRequestType: int, bRequest: int,
                      wValue: int, wIndex: int, data: array.array, timeout: int) -> int:
        self._check(dev_handle)
        kind = bmRequestType & 0x60
        with dev_handle.lock:
            if bmRequestType & 0x80:  # device to host
                if kind == 0 and bRequest == _GET_DESCRIPTOR:
                    reply = self._descriptor(dev_handle, wValue >> 8, wValue & 0xFF)
                elif kind == 0x40 and bRequest == SCANN_CHANNELS:
                    reply = dev_handle.scan_result
                else:
                    reply = None
                if reply is None:
                    raise _usb_error("Pipe error", errno.EPIPE)
                n = min(len(reply), len(data))
                data[:n] = array.array("B", reply[:n])
                return n
            if kind != 0x40 or not dev_handle.vendor_out(bRequest, wValue, wIndex,
                                                         bytes(data)):
                raise _usb_error("Pipe error", errno.EPIPE)
            return len(data)

    @staticmethod
    def _descriptor(dev: EmulatedCrazyradio, kind: int, index: int) -> bytes | None:
        if kind == DESC_DEVICE:
            return dev.device_descriptor_bytes()
        if kind == _DESC_CONFIG:
            return _CONFIG_BYTES
        if kind == _DESC_STRING:
            if index == 0:
                return bytes([4, 3, 0x09, 0x04])  # English (United States)
            text = dev.strings().get(index)
            if text is None:
                return None
            raw = text.encode("utf-16-le")
            return bytes([2 + len(raw), 3]) + raw
        return None


# ---------------------------------------------------------------------- the hook
@dataclass
class EmulatedBus:
    """The emulated USB bus while :func:`emulated_radio` is active."""

    backend: EmulatedUsbBackend
    vehicles: list[RadioVehicle]

    @property
    def dongles(self) -> list[EmulatedCrazyradio]:
        return self.backend.dongles

    def vehicle_for_uri(self, uri: str) -> RadioVehicle | None:
        """The vehicle a ``radio://N/channel/rate/address`` URI reaches, if any."""
        from cflib.crtp.radiodriver import RadioDriver

        try:
            _, channel, rate, address, _ = RadioDriver.parse_uri(uri.split("?")[0])
        except Exception:
            return None
        for v in self.vehicles:
            if v.heard_on(channel=channel, rate=rate, address=bytes(address)):
                return v
        return None


_bus: EmulatedBus | None = None
_bus_lock = threading.Lock()


def installed_bus() -> EmulatedBus | None:
    """The emulated bus in use, if any."""
    return _bus


def usb_backend() -> Any:
    """The pyusb backend the ground station and cflib use: the emulated bus inside
    :func:`emulated_radio`, else libusb 1.0 as cflib picks it (``libusb_package``)."""
    bus = _bus
    if bus is not None:
        return bus.backend
    import libusb_package

    return _real_get_backend(libusb_package)()


def _real_get_backend(module: Any) -> Any:
    return getattr(module, "_groundstation_real_get_libusb1_backend",
                   module.get_libusb1_backend)


@contextlib.contextmanager
def emulated_radio(
    *, vehicles: Sequence[dict[str, Any]] | None = None, speed: float = 1.0, loss: float = 0.0,
    bit_error_rate: float = 0.0, firmware_bcd: int = FIRMWARE_BCD, seed: int = 0,
    dongles: int = 1,
) -> Iterator[EmulatedBus]:
    """Put ``dongles`` emulated Crazyradio PAs on an emulated USB bus, with simulated vehicles.

    ``vehicles`` are keyword dicts for :class:`RadioVehicle` (``channel``, ``data_rate``,
    ``address``, ``safelink_capable``, ``faults``) plus ``seed``; default: one on channel 80, 2M,
    E7E7E7E7E7. Each runs at ``speed``. ``loss`` (per transmission) and ``bit_error_rate`` (per
    bit on air) are the noise between every dongle and every vehicle
    (:class:`~groundstation.sim.radio_noise.RadioNoise`). While active, cflib's ``radio://``
    driver finds the emulated dongles (and no real one) and flights over ``radio://`` to a vehicle
    run on its simulation clock. On exit the vehicles power off and cflib's cached radios are
    forgotten.
    """
    global _bus
    import libusb_package
    from cflib.crtp.radiodriver import RadioManager

    noise = RadioNoise(loss=loss, bit_error_rate=bit_error_rate)  # ValueError when out of range
    with _bus_lock:
        if _bus is not None:
            raise RuntimeError("an emulated radio is already installed")
        made = []
        for i, spec in enumerate([{}] if vehicles is None else vehicles):
            opts = dict(spec)
            sim = Simulator(address=f"radio-{i}", speed=speed, linger=False,
                            seed=int(opts.pop("seed", seed + i)), max_backlog=_MAX_BACKLOG)
            made.append(RadioVehicle(sim=sim, **opts))
        radios = [EmulatedCrazyradio(vehicles=made, noise=noise, firmware_bcd=firmware_bcd,
                                     seed=seed + k, serial=f"E7E7E7E7{k:02X}",
                                     bus_address=7 + k) for k in range(dongles)]
        bus = _bus = EmulatedBus(backend=EmulatedUsbBackend(radios), vehicles=made)
        real = libusb_package.get_libusb1_backend
        libusb_package._groundstation_real_get_libusb1_backend = real
        libusb_package.get_libusb1_backend = lambda *a, **kw: bus.backend
    try:
        yield bus
    finally:
        with _bus_lock:
            libusb_package.get_libusb1_backend = real
            del libusb_package._groundstation_real_get_libusb1_backend
            _bus = None
        for d in radios:
            d.plugged = False
        for i in range(len(RadioManager._radios)):
            RadioManager.remove(i)  # a cached radio would hold an emulated device
        for v in made:
            v.detach()
            v.sim.close()


class _HeardTime:
    """A vehicle's simulated time as a flight clock sees it: the flight's scheduler paces the
    simulation (:meth:`Simulator.pace`) only while the vehicle hears the ground station; out of
    range, switched off or unplugged, its time runs on (and its watchdog with it)."""

    def __init__(self, vehicle: RadioVehicle) -> None:
        self._vehicle, self._sim = vehicle, vehicle.sim
        self.speed, self.cond = vehicle.sim.speed, vehicle.sim.cond

    @property
    def published_s(self) -> float:
        return self._sim.published_s

    @property
    def running(self) -> bool:
        return self._sim.running

    def pace(self, *, until_s: float) -> None:
        if self._vehicle.attached:
            self._sim.pace(until_s=until_s)


def _clock_for(uri: str) -> Clock | None:
    bus = _bus
    vehicle = None if bus is None else bus.vehicle_for_uri(uri)
    return None if vehicle is None else SimClock(source=_HeardTime(vehicle))


register_clock("radio", _clock_for)
