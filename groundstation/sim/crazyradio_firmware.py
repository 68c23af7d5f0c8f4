"""The emulated Crazyradio PA's firmware and radio, and the simulated Crazyflie's radio it talks to.

:class:`EmulatedCrazyradio` keeps the dongle's configuration and answers its vendor requests and
bulk packets as bitcraze/crazyradio-firmware does:

* ``firmware/src/usbDescriptor.c``: VID 0x1915, PID 0x7777, strings "Bitcraze" and
  "Crazyradio PA USB Dongle", serial at string index 0x1D; ``bcdDevice`` is the firmware version
  (0x0053 = 0.53, what a released Crazyradio PA reports; cflib reads it as ``version``).
* ``firmware/src/main.c``: vendor requests (SET_RADIO_CHANNEL 0x01 .. LAUNCH_BOOTLOADER 0xFF,
  anything else stalls), a bulk OUT packet (at most 32 bytes) sent with auto-ack and answered on
  EP1 IN with ``[status, ack payload...]``, ``status = ack | power detector << 1 | retries << 4``
  (0 when no ack came back), no IN transfer with ACK_ENABLE off or a continuous carrier on,
  SCANN_CHANNELS (0x40: scan ``wValue..wIndex``, every second channel at 2M; 0xC0: the result).
* ``firmware/src/radio.c``: channel 0..125 else ignored, data rate < 3 else ignored, power & 3,
  ARC (retries) & 0x0F; defaults channel 2, 2M, 0 dBm, ARC 3.

:class:`RadioVehicle` is a simulated Crazyflie's nRF51 in PRX mode in front of a
:class:`~groundstation.sim.simulator.Simulator` (bitcraze/crazyflie2-nrf-firmware ``src/esb.c``):
it hears only its channel, data rate and address; each received packet is acked with the head of its
downlink queue (an empty ``0xF3`` ack otherwise), and without safelink a received packet releases
the payload sent last whether its ack arrived or not (``setupTx``: "No retry, TX payload has been
sent!"), so a lost ack loses that payload. With *safelink* (enabled by ``[0xFF, 0x05, 1]``; a
vehicle with ``safelink_capable=False`` is one whose nRF firmware predates it) header bit 3 (up)
drops duplicated uplink packets and bit 2 (down) keeps a downlink packet until the host confirms
it, so lost acks lose no data. The air between them is :mod:`groundstation.sim.radio_noise`.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any, Literal

from groundstation.sim.radio_noise import Air, RadioNoise, RadioStats
from groundstation.sim.simulator import Simulator
from groundstation.sim.uri import Faults

__all__ = ["FIRMWARE_BCD", "PID", "VID", "DataRate", "EmulatedCrazyradio", "RadioVehicle"]

VID, PID = 0x1915, 0x7777
FIRMWARE_BCD = 0x0053  # Crazyradio PA release 0.53
SET_RADIO_CHANNEL, SET_RADIO_ADDRESS, SET_DATA_RATE, SET_RADIO_POWER = 0x01, 0x02, 0x03, 0x04
SET_RADIO_ARD, SET_RADIO_ARC, ACK_ENABLE, SET_CONT_CARRIER = 0x05, 0x06, 0x10, 0x20
SCANN_CHANNELS, LAUNCH_BOOTLOADER = 0x21, 0xFF
DESC_DEVICE = 1
SERIAL_INDEX = 0x1D
_MAX_SCANN_LENGTH = 63

DataRate = Literal["250K", "1M", "2M"]
_RATES: dict[str, int] = {"250K": 0, "1M": 1, "2M": 2}


def _address_bytes(address: int) -> bytes:
    """A 40-bit radio address as cflib sends it (``struct.unpack('<BBBBB', unhexlify(...))``:
    most significant byte first)."""
    return address.to_bytes(5, "big")


@dataclass
class RadioVehicle:
    """A simulated Crazyflie's radio (nRF51 ESB in PRX mode) in front of a :class:`Simulator`.

    :meth:`leave_range` (out of range: the vehicle flies on, hears nothing, its watchdog stops it)
    and :meth:`power_off` make it stop answering; either way the dongle gets no more acks."""

    sim: Simulator
    channel: int = 80
    data_rate: DataRate = "2M"
    address: int = 0xE7E7E7E7E7
    faults: Faults | None = None
    safelink_capable: bool = True
    safelink: bool = False
    curr_up: int = 1
    curr_down: int = 1
    received: int = 0  # packets handed to the CRTP side (duplicates excluded)
    duplicates: int = 0
    in_range: bool = True
    _token: int = 0
    _pending: deque = field(default_factory=deque)  # downlink packets not yet released
    _last: bytes | None = None  # the ack payload sent last
    _last_queued: bool = False  # ... and whether it came from the queue
    _lock: threading.RLock = field(default_factory=threading.RLock)

    @property
    def attached(self) -> bool:
        """Whether the ground station's packets reach the simulation now."""
        return self._token != 0

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

    def hear(self, data: bytes) -> bytes | None:
        """The ack payload for one packet that reached the vehicle (``src/esb.c``,
        ``esbInterruptHandler``); ``None`` when it is out of range or off."""
        with self._lock:
            if not self.in_range:
                return None
            return self._on_packet(data)

    def _on_packet(self, data: bytes) -> bytes:
        if (self.safelink_capable and len(data) == 3 and data[0] & 0xF3 == 0xF3
                and data[1] == 0x05):  # safelink request: answered by the service packet
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
            if self._last_queued and self._pending:  # sent (and, with safelink, confirmed)
                self._pending.popleft()
            self._last, self._last_queued = self._next_down()
        return self._last

    def detach(self) -> None:
        """Nothing heard from the host any more: release the simulation's pacing (the
        firmware resets logging after a silent second; this does it at once)."""
        with self._lock:
            # token 0 (attached no more): still ends a scheduler's hold on the simulation's time
            token, self._token = self._token, 0
            self.sim.detach(token=token)
            self._pending.clear()
            self._last, self._last_queued = None, False

    def leave_range(self) -> None:
        """Out of range: the vehicle flies on but hears nothing (and nothing it sends arrives)."""
        with self._lock:
            self.in_range = False
            self.detach()

    def power_off(self) -> None:
        """Switched off (battery out): silent on the radio and its simulation stopped."""
        self.leave_range()
        self.sim.close()


class EmulatedCrazyradio:
    """One emulated Crazyradio PA: its configuration (as the firmware keeps it), its radio, its
    statistics and its USB state. ``noise`` is the air to every vehicle (default: none)."""

    def __init__(self, *, vehicles: Sequence[RadioVehicle] = (), serial: str = "E7E7E7E7E7",
                 firmware_bcd: int = FIRMWARE_BCD, noise: RadioNoise | None = None,
                 seed: int = 0, bus_address: int = 7) -> None:
        self.vehicles, self.serial, self.firmware_bcd = list(vehicles), serial, firmware_bcd
        self.noise, self.bus_address = noise or RadioNoise(), bus_address
        self.channel, self.data_rate, self.power = 2, 2, 3
        self.address = b"\xe7" * 5
        self.arc, self.ard, self.ack_enable, self.cont_carrier = 3, 0x80 | 32, True, False
        self.bootloader_requested = False
        self.plugged, self.open_handles, self.configuration = True, 0, 0
        self.stats = RadioStats()
        self.air = Air(noise=self.noise, seed=seed, stats=self.stats)
        self._in: deque[bytes] = deque()
        self.scan_result = b""
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

    def set_noise(self, noise: RadioNoise) -> None:
        """Change the air from the next transmission on (a vehicle flying into noise)."""
        with self.lock:
            self.noise = self.air.noise = noise

    def _listener(self) -> RadioVehicle | None:
        return next((v for v in self.vehicles if v.heard_on(
            channel=self.channel, rate=self.data_rate, address=self.address)), None)

    def transmit(self, data: bytes) -> tuple[bool, int, bytes]:
        """Send one packet with auto-retry (``radioSendPacket``): (acked, retries, payload)."""
        vehicle, air = self._listener(), self.air
        for attempt in range(self.arc + 1):
            if vehicle is None or not air.through(len(data)):
                continue
            payload = vehicle.hear(data)
            if payload is not None and air.through(len(payload)):
                return True, attempt, payload
        return False, self.arc, b""

    def bulk_out(self, data: bytes) -> bool:
        """EP1 OUT: one radio packet (``main.c`` main loop). Whether data moved (a packet
        other than a null packet up, or a payload down)."""
        if self.cont_carrier:
            return False
        data = bytes(data[:32])
        if not self.ack_enable:
            vehicle = self._listener()
            if vehicle is not None and self.air.through(len(data)):
                vehicle.hear(data)
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
        self.scan_result = bytes(found)

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
        return {1: "Bitcraze", 2: "Crazyradio PA USB Dongle", SERIAL_INDEX: self.serial}

    def device_descriptor(self) -> SimpleNamespace:
        return SimpleNamespace(
            bLength=18, bDescriptorType=DESC_DEVICE, bcdUSB=0x0200, bDeviceClass=0,
            bDeviceSubClass=0, bDeviceProtocol=0, bMaxPacketSize0=64, idVendor=VID,
            idProduct=PID, bcdDevice=self.firmware_bcd, iManufacturer=1, iProduct=2,
            iSerialNumber=SERIAL_INDEX, bNumConfigurations=1, address=self.bus_address, bus=1,
            port_number=1, port_numbers=(1,), speed=2)  # speed 2: full speed (12 Mbit/s)

    def device_descriptor_bytes(self) -> bytes:
        d = self.device_descriptor()
        return bytes([18, 1, 0x00, 0x02, 0, 0, 0, 64, VID & 0xFF, VID >> 8, PID & 0xFF, PID >> 8,
                      d.bcdDevice & 0xFF, d.bcdDevice >> 8, 1, 2, SERIAL_INDEX, 1])
