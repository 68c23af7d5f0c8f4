"""An emulated Crazyradio PA on an emulated USB bus: a pyusb backend cflib drives unmodified.

cflib reaches a Crazyradio through pyusb (``cflib/drivers/crazyradio.py``: ``usb.core.find(
idVendor=0x1915, idProduct=0x7777, backend=libusb_package.get_libusb1_backend())``, vendor
control requests, bulk EP1 OUT/IN). :class:`EmulatedUsbBackend` is a ``usb.backend.IBackend``
presenting the dongle's descriptors and implementing its firmware, after
bitcraze/crazyradio-firmware:

* ``firmware/src/usbDescriptor.c``: VID 0x1915, PID 0x7777, one configuration, interface 0
  (vendor class) with bulk EP 0x81 IN and 0x01 OUT of 64 bytes, strings "Bitcraze" and
  "Crazyradio PA USB Dongle", serial at string index 0x1D; ``bcdDevice`` is the firmware version
  (0x0053 = 0.53, what a released Crazyradio PA reports; cflib reads it as ``version``).
* ``firmware/src/main.c``: vendor requests (SET_RADIO_CHANNEL 0x01 .. LAUNCH_BOOTLOADER 0xFF,
  anything else stalls), a bulk OUT packet (at most 32 bytes) sent with auto-ack and answered on
  EP1 IN with ``[status, ack payload...]``, ``status = ack | power detector << 1 | retries << 4``
  (0 when no ack came back), no IN transfer with ACK_ENABLE off or a continuous carrier on,
  SCANN_CHANNELS (0x40: scan ``wValue..wIndex``, every second channel at 2M; 0xC0: the result).
* ``firmware/src/radio.c``: channel 0..125 else ignored, data rate < 3 else ignored, power & 3,
  ARC (retries) & 0x0F; defaults channel 2, 2M, 0 dBm, ARC 3.

The radio side delivers packets to :class:`RadioVehicle` s (a :class:`Simulator`, the simulated
Crazyflie ``sim://`` uses) on the same channel, data rate and address only. The vehicle's radio
answers as the Crazyflie's nRF51 does (bitcraze/crazyflie2-nrf-firmware ``src/esb.c``): each
received packet is acked with the head of its downlink queue (an empty ``0xF3`` ack otherwise);
with *safelink* (enabled by ``[0xFF, 0x05, 1]``) header bit 3 (up) drops duplicated uplink
packets and bit 2 (down) keeps a downlink packet until the host confirms it, so lost acks lose no
data. ``loss`` is the probability that one transmission (the packet, or its ack) is lost; each
loss costs a retry (the ``retries`` nibble, from which cflib computes link quality) and ARC + 1
failed attempts fail the transfer (``status = 0``).

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
import random
import threading
import time
from collections import deque
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any, Literal

import usb.backend
import usb.core

from groundstation.flight.clock import Clock, register_clock
from groundstation.sim.simulator import Faults, Simulator

__all__ = ["DataRate", "EmulatedBus", "EmulatedCrazyradio", "EmulatedUsbBackend", "RadioStats",
           "RadioVehicle", "emulated_radio", "expected_link_quality", "installed_bus",
           "usb_backend"]

log = logging.getLogger(__name__)

VID, PID = 0x1915, 0x7777
FIRMWARE_BCD = 0x0053  # Crazyradio PA release 0.53
SET_RADIO_CHANNEL, SET_RADIO_ADDRESS, SET_DATA_RATE, SET_RADIO_POWER = 0x01, 0x02, 0x03, 0x04
SET_RADIO_ARD, SET_RADIO_ARC, ACK_ENABLE, SET_CONT_CARRIER = 0x05, 0x06, 0x10, 0x20
SCANN_CHANNELS, LAUNCH_BOOTLOADER = 0x21, 0xFF
_GET_DESCRIPTOR, _DESC_DEVICE, _DESC_CONFIG, _DESC_STRING = 0x06, 1, 2, 3
_MAX_SCANN_LENGTH = 63
_SERIAL_INDEX = 0x1D
_ERROR_DELAY_S = 0.001  # a failed USB transfer still costs about a frame
_MAX_BACKLOG = 4  # downlink packets a vehicle lets wait before its simulated time holds
_IDLE_POLL_S = 0.001  # an exchange that moved no data costs a USB round trip (about 1 ms)

DataRate = Literal["250K", "1M", "2M"]
_RATES: dict[str, int] = {"250K": 0, "1M": 1, "2M": 2}


def _usb_error(text: str, code: int) -> usb.core.USBError:
    if code == errno.ETIMEDOUT:
        return usb.core.USBTimeoutError(text, error_code=-7, errno=code)
    return usb.core.USBError(text, error_code=-1, errno=code)


def _address_bytes(address: int) -> bytes:
    """A 40-bit radio address as cflib sends it (``struct.unpack('<BBBBB', unhexlify(...))``:
    most significant byte first)."""
    return address.to_bytes(5, "big")


@dataclass
class RadioVehicle:
    """A simulated Crazyflie's radio (nRF51 ESB in PRX mode) in front of a :class:`Simulator`."""

    sim: Simulator
    channel: int = 80
    data_rate: DataRate = "2M"
    address: int = 0xE7E7E7E7E7
    faults: Faults | None = None
    safelink: bool = False
    curr_up: int = 1
    curr_down: int = 1
    received: int = 0  # packets handed to the CRTP side (duplicates excluded)
    duplicates: int = 0
    _token: int = 0
    _pending: deque = field(default_factory=deque)  # downlink packets not yet confirmed
    _last: bytes | None = None  # the ack payload sent last
    _last_queued: bool = False  # ... and whether it came from the queue

    def heard_on(self, *, channel: int, rate: int, address: bytes) -> bool:
        return (channel == self.channel and rate == _RATES[self.data_rate]
                and address == _address_bytes(self.address))

    def _deliver(self, data: bytes) -> None:
        if not self._token:
            self._token = self.sim.attach(faults=self.faults)
        if len(data) >= 1 and data[0] & 0xF3 != 0xF3:  # null packets stop at the radio
            self.sim.submit(header=data[0], data=data[1:], token=self._token)

    def _next_down(self) -> tuple[bytes, bool]:
        if not self._pending and self._token:
            got = self.sim.receive(token=self._token, wait=0)
            if got is not None:
                self._pending.append(bytes([got[0]]) + got[1])
        if self._pending:
            pk = self._pending[0]
            if self.safelink:
                pk = bytes([(pk[0] & 0xF3) | self.curr_down << 2]) + pk[1:]
            return pk, True
        return bytes([0xF3 | self.curr_down << 2]), False

    def on_packet(self, data: bytes) -> bytes:
        """The ack payload for one packet received (``src/esb.c``, ``esbInterruptHandler``)."""
        if len(data) == 3 and data[0] & 0xF3 == 0xF3 and data[1] == 0x05:  # safelink request
            self.safelink, self.curr_up, self.curr_down = bool(data[2]), 1, 1
            self._last, self._last_queued = bytes(data), False
            return bytes(data)
        if not self.safelink or (data[0] & 0x08) != self.curr_up << 3:
            self.received += 1
            self.curr_up = 1 - self.curr_up
            self._deliver(bytes(data))
        else:
            self.duplicates += 1
        if not self.safelink or (data[0] & 0x04) != self.curr_down << 2 or self._last is None:
            self.curr_down = 1 - self.curr_down
            if self._last_queued and self._pending:  # the host has confirmed it
                self._pending.popleft()
            self._last, self._last_queued = self._next_down()
        return self._last

    def detach(self) -> None:
        """Nothing heard from the host any more: release the simulation's pacing (the
        firmware resets logging after a silent second; this does it at once)."""
        if self._token:
            self.sim.detach(token=self._token)
            self._token = 0
        self._pending.clear()
        self._last, self._last_queued = None, False


@dataclass
class RadioStats:
    """What the emulated dongle did: transfers, their attempts and retries, failures."""

    transfers: int = 0
    acked: int = 0
    failed: int = 0
    retries: list[int] = field(default_factory=list)  # per transfer: retries, ARC if failed
    ok: list[bool] = field(default_factory=list)  # per transfer: acked

    def link_quality(self) -> float:
        """cflib's link quality over these transfers: ``10 * (10 - mean retries)`` of the acked
        ones (cflib skips its statistics for a transfer without ack)."""
        acked = [r for r, ok in zip(self.retries, self.ok, strict=True) if ok]
        return 10.0 * (10.0 - sum(acked) / len(acked)) if acked else 0.0


def expected_link_quality(*, loss: float, arc: int = 3) -> float:
    """The link quality cflib reports when each transmission (packet or ack) is lost with
    probability ``loss``: an attempt gets through with ``q = (1 - loss)^2``, ``k`` retries
    happen with ``(1 - q)^k q`` for ``k <= arc``, and cflib averages ``10 (10 - k)`` over the
    acked transfers."""
    q = (1.0 - loss) ** 2
    p = [(1.0 - q) ** k * q for k in range(arc + 1)]
    if sum(p) == 0.0:
        return 0.0
    return 10.0 * (10.0 - sum(k * pk for k, pk in enumerate(p)) / sum(p))


class EmulatedCrazyradio:
    """One emulated Crazyradio PA: its configuration (as the firmware keeps it), its radio and
    its USB state. ``loss`` is the probability that one transmission is lost (each way)."""

    def __init__(self, *, vehicles: Sequence[RadioVehicle] = (), serial: str = "E7E7E7E7E7",
                 firmware_bcd: int = FIRMWARE_BCD, loss: float = 0.0, seed: int = 0,
                 bus_address: int = 7) -> None:
        if not 0.0 <= loss <= 1.0:
            raise ValueError(f"loss must be in [0, 1], got {loss}")
        self.vehicles, self.serial, self.firmware_bcd = list(vehicles), serial, firmware_bcd
        self.loss, self.bus_address = loss, bus_address
        self.channel, self.data_rate, self.power = 2, 2, 3
        self.address = b"\xe7" * 5
        self.arc, self.ard, self.ack_enable, self.cont_carrier = 3, 0x80 | 32, True, False
        self.bootloader_requested = False
        self.plugged, self.open_handles, self.configuration = True, 0, 0
        self.stats = RadioStats()
        self._rng = random.Random(seed * 7919 + 5)
        self._in: deque[bytes] = deque()
        self._scan_result = b""
        self.lock = threading.RLock()

    # ------------------------------------------------------------------ the radio
    @property
    def data_rate_name(self) -> DataRate:
        return {0: "250K", 1: "1M", 2: "2M"}[self.data_rate]  # type: ignore[return-value]

    def configured(self) -> dict[str, Any]:
        """Channel, data rate and address as the dongle holds them now (for tests)."""
        return {"channel": self.channel, "data_rate": self.data_rate_name,
                "address": self.address.hex().upper(), "power": self.power, "arc": self.arc,
                "ack_enable": self.ack_enable, "cont_carrier": self.cont_carrier}

    def _lost(self) -> bool:
        return self.loss > 0.0 and self._rng.random() < self.loss

    def transmit(self, data: bytes) -> tuple[bool, int, bytes]:
        """Send one packet with auto-retry (``radioSendPacket``): (acked, retries, payload)."""
        vehicle = next((v for v in self.vehicles if v.heard_on(
            channel=self.channel, rate=self.data_rate, address=self.address)), None)
        for attempt in range(self.arc + 1):
            if vehicle is None or self._lost():
                continue
            payload = vehicle.on_packet(data)
            if not self._lost():
                return True, attempt, payload
        return False, self.arc, b""

    def _send_no_ack(self, data: bytes) -> None:
        vehicle = next((v for v in self.vehicles if v.heard_on(
            channel=self.channel, rate=self.data_rate, address=self.address)), None)
        if vehicle is not None and not self._lost():
            vehicle.on_packet(data)

    def bulk_out(self, data: bytes) -> bool:
        """EP1 OUT: one radio packet (``main.c`` main loop). Whether data moved (a packet
        other than a null packet up, or a payload down)."""
        if self.cont_carrier:
            return False
        data = bytes(data[:32])
        if not self.ack_enable:
            self._send_no_ack(data)
            return True
        acked, retries, payload = self.transmit(data)
        st = self.stats
        st.transfers += 1
        st.retries.append(retries)
        st.ok.append(acked)
        if acked:
            st.acked += 1
            self._in.append(bytes([1 | 0x02 | retries << 4]) + payload)
            return len(payload) > 1 or data[0] & 0xF3 != 0xF3
        st.failed += 1
        self._in.append(b"\x00")
        return False

    def bulk_in(self) -> bytes | None:
        return self._in.popleft() if self._in else None

    def scan(self, *, start: int, stop: int, packet: bytes) -> None:
        """START_SCAN_CHANNELS: the channels in ``start..stop`` that ack ``packet``."""
        found = []
        step = 2 if self.data_rate == 2 else 1
        for ch in range(start, min(stop, 125) + 1, step):
            if len(found) >= _MAX_SCANN_LENGTH:
                break
            self.channel = ch
            if self.transmit(packet)[0]:
                found.append(ch)
        self._scan_result = bytes(found)

    def vendor_out(self, request: int, value: int, index: int, data: bytes) -> bool:
        """A host-to-device vendor request; ``False`` stalls (``handleUsbVendorSetup``)."""
        if request == SET_RADIO_CHANNEL:
            if 0 <= value <= 125:
                self.channel = value
        elif request == SET_RADIO_ADDRESS:
            if len(data) != 5:
                return False
            self.address = bytes(data)
        elif request == SET_DATA_RATE:
            if value < 3:
                self.data_rate = value
        elif request == SET_RADIO_POWER:
            self.power = value & 0x03
        elif request == SET_RADIO_ARD:
            self.ard = value & 0xFF
        elif request == SET_RADIO_ARC:
            self.arc = value & 0x0F
        elif request == ACK_ENABLE:
            self.ack_enable = bool(value)
        elif request == SET_CONT_CARRIER:
            self.cont_carrier = bool(value)
        elif request == SCANN_CHANNELS:
            if len(data) < 1:
                return False
            self.scan(start=value, stop=index, packet=bytes(data))
        elif request == LAUNCH_BOOTLOADER:
            self.bootloader_requested = True
        else:
            return False
        return True

    def unplug(self) -> None:
        """Pull the dongle out: every transfer fails with ENODEV from now on."""
        with self.lock:
            self.plugged = False
            for v in self.vehicles:
                v.detach()

    # ------------------------------------------------------------------ descriptors
    def strings(self) -> dict[int, str]:
        return {1: "Bitcraze", 2: "Crazyradio PA USB Dongle", _SERIAL_INDEX: self.serial}

    def device_descriptor(self) -> SimpleNamespace:
        return SimpleNamespace(
            bLength=18, bDescriptorType=_DESC_DEVICE, bcdUSB=0x0200, bDeviceClass=0,
            bDeviceSubClass=0, bDeviceProtocol=0, bMaxPacketSize0=64, idVendor=VID,
            idProduct=PID, bcdDevice=self.firmware_bcd, iManufacturer=1, iProduct=2,
            iSerialNumber=_SERIAL_INDEX, bNumConfigurations=1, address=self.bus_address, bus=1,
            port_number=1, port_numbers=(1,), speed=2)  # speed 2: full speed (12 Mbit/s)

    def device_descriptor_bytes(self) -> bytes:
        d = self.device_descriptor()
        return bytes([18, 1, 0x00, 0x02, 0, 0, 0, 64, VID & 0xFF, VID >> 8, PID & 0xFF, PID >> 8,
                      d.bcdDevice & 0xFF, d.bcdDevice >> 8, 1, 2, _SERIAL_INDEX, 1])


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
                    reply = dev_handle._scan_result
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
        if kind == _DESC_DEVICE:
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
    firmware_bcd: int = FIRMWARE_BCD, seed: int = 0, dongles: int = 1,
) -> Iterator[EmulatedBus]:
    """Put ``dongles`` emulated Crazyradio PAs on an emulated USB bus, with simulated vehicles.

    ``vehicles`` are keyword dicts for :class:`RadioVehicle` (``channel``, ``data_rate``,
    ``address``) plus ``seed``; default: one on channel 80, 2M, E7E7E7E7E7. Each runs at
    ``speed``. While active, cflib's ``radio://`` driver finds the emulated dongles (and no real
    one) and flights over ``radio://`` to a vehicle run on its simulation clock. On exit the
    vehicles power off and cflib's cached radios are forgotten.
    """
    global _bus
    import libusb_package
    from cflib.crtp.radiodriver import RadioManager

    specs = [{}] if vehicles is None else list(vehicles)
    made = []
    for i, spec in enumerate(specs):
        opts = dict(spec)
        sim = Simulator(address=f"radio-{i}", speed=speed, seed=int(opts.pop("seed", seed + i)),
                        linger=False, max_backlog=_MAX_BACKLOG)
        made.append(RadioVehicle(sim=sim, **opts))
    radios = [EmulatedCrazyradio(vehicles=made, loss=loss, firmware_bcd=firmware_bcd,
                                 seed=seed + k, serial=f"E7E7E7E7{k:02X}", bus_address=7 + k)
              for k in range(dongles)]
    bus = EmulatedBus(backend=EmulatedUsbBackend(radios), vehicles=made)
    with _bus_lock:
        if _bus is not None:
            raise RuntimeError("an emulated radio is already installed")
        _bus = bus
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


def _clock_for(uri: str) -> Clock | None:
    bus = _bus
    vehicle = None if bus is None else bus.vehicle_for_uri(uri)
    return None if vehicle is None else vehicle.sim.clock


register_clock("radio", _clock_for)
