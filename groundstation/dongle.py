"""The Crazyradio as the ground station checks it before cflib opens it, and what it configured.

cflib's own errors for a missing or outdated dongle are unhelpful (``Cannot find a Crazyradio
Dongle``; for firmware older than 0.3 it raises a string, a ``TypeError``), so ``radio://`` flights
check first: :func:`check_dongle` names the problem and the fix in one line. The USB backend is the
one cflib uses (:func:`groundstation.sim.crazyradio_usb.usb_backend`: libusb 1.0, or the emulated
bus inside ``emulated_radio``).
"""

from __future__ import annotations

import logging
from typing import Any

from groundstation.errors import LinkError

__all__ = ["MIN_FIRMWARE", "UDEV_HINT", "check_dongle", "crazyradios", "firmware_version",
           "radio_metadata"]

log = logging.getLogger(__name__)

MIN_FIRMWARE = 0.4
"""Oldest Crazyradio firmware cflib fully drives (below 0.4 it sets no auto-retry or address;
below 0.3 it refuses the dongle)."""
UDEV_HINT = ("add the udev rule from docs/flying.md (SUBSYSTEM==\"usb\", "
             "ATTRS{idVendor}==\"1915\", ATTRS{idProduct}==\"7777\", MODE=\"0664\", "
             "GROUP=\"plugdev\"), then replug")
_RATE_NAMES = {0: "250K", 1: "1M", 2: "2M"}


def firmware_version(bcd: int) -> float:
    """The firmware version of a ``bcdDevice`` as cflib reads it (0x0053 -> 0.53)."""
    return float(f"{bcd >> 8:x}.{bcd & 0xFF:x}")


def crazyradios() -> list[Any]:
    """The Crazyradios on USB (pyusb devices, in cflib's order). A missing libusb raises a
    one-line :class:`LinkError`."""
    import usb.core

    from groundstation.sim.crazyradio_usb import usb_backend

    try:
        return list(usb.core.find(find_all=True, idVendor=0x1915, idProduct=0x7777,
                                  backend=usb_backend()) or ())
    except usb.core.NoBackendError:
        raise LinkError("no USB backend (libusb) found; install it (Debian/Ubuntu: "
                        "sudo apt install libusb-1.0-0) and retry") from None


def check_dongle(uri: str) -> None:
    """For a ``radio://N/...`` URI: dongle ``N`` is on USB with firmware >= :data:`MIN_FIRMWARE`,
    else a one-line :class:`LinkError` with the fix (other URIs: nothing to check)."""
    if not uri.startswith("radio://"):
        return
    dev_id = uri[len("radio://"):].split("/", 1)[0]
    if not dev_id.isdigit():
        return  # a dongle named by serial: cflib looks it up and names it if missing
    radios = crazyradios()
    if not radios:
        raise LinkError(f"cannot connect to {uri}: no Crazyradio found on USB; plug in a "
                        f"Crazyradio PA (1915:7777), or if it is plugged in, {UDEV_HINT}; "
                        "without one, fly the simulator: --uri sim://0")
    if int(dev_id) >= len(radios):
        raise LinkError(f"cannot connect to {uri}: there is no Crazyradio {dev_id} (found "
                        f"{len(radios)}; they count from 0); groundstation scan lists them")
    version = firmware_version(radios[int(dev_id)].bcdDevice)
    if version < MIN_FIRMWARE:
        raise LinkError(f"cannot connect to {uri}: the Crazyradio's firmware is {version:g}, "
                        f"older than {MIN_FIRMWARE:g}; update it (cfloader, see "
                        "https://www.bitcraze.io/documentation/repository/crazyradio-firmware/"
                        "master/building/building_flashing/) and replug")


def radio_metadata(cf: Any) -> dict[str, Any]:
    """``{"radio": {...}}`` for a Crazyflie connected over ``radio://``: the channel, data rate
    and address cflib configures on the dongle for this link (its own URI parser) and the
    dongle's firmware version; ``{}`` for other links."""
    link = getattr(cf, "link", None)
    uri = str(getattr(link, "uri", "") or "")
    if not uri.startswith("radio://"):
        return {}
    from cflib.crtp.radiodriver import RadioDriver

    try:
        dev_id, channel, rate, address, _ = RadioDriver.parse_uri(uri)
    except Exception:  # the link is up, so this parsed once; never fail a flight over it
        log.debug("cannot parse %s", uri, exc_info=True)
        return {}
    version = getattr(getattr(link, "_radio", None), "version", None)
    return {"radio": {"dongle": int(dev_id), "channel": int(channel),
                      "data_rate": _RATE_NAMES.get(rate, str(rate)),
                      "address": bytes(address).hex().upper(),
                      "dongle_firmware": None if version is None else float(version)}}
