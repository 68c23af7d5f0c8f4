"""``groundstation scan``: Crazyradios and Crazyflies on USB (pyusb), Crazyflies in reach (cflib).

Without a Crazyradio, or without permission to open it, the command names the problem and the fix
in one line (the udev rule is in ``docs/flying.md``) and exits 2, unless some other link (the
simulator, a UDP peer) found a Crazyflie, in which case it lists those and warns.
"""

from __future__ import annotations

import contextlib
import io
import logging
import string
from typing import Any

import click

from groundstation.dongle import UDEV_HINT, firmware_version
from groundstation.errors import LinkError

__all__ = ["USB_IDS", "command", "find_usb_devices", "scan_crazyflies"]

log = logging.getLogger(__name__)

USB_IDS = {
    (0x1915, 0x7777): "Crazyradio PA / 2.0",
    (0x0483, 0x5740): "Crazyflie 2.x (USB cable)",
}


def find_usb_devices() -> list[dict[str, Any]]:
    """Crazyradios and USB-connected Crazyflies: ``name``, ``vid``, ``pid``, ``bus``,
    ``address``, ``serial``. A missing libusb or a permission problem raises a one-line
    :class:`LinkError` with the fix."""
    import usb.core
    import usb.util

    from groundstation.sim.crazyradio_usb import usb_backend

    found = []
    try:
        backend = usb_backend()  # cflib's choice: libusb 1.0, or the emulated bus
        for (vid, pid), name in USB_IDS.items():
            for dev in usb.core.find(find_all=True, idVendor=vid, idProduct=pid,
                                     backend=backend) or ():
                try:
                    index = dev.iSerialNumber
                    serial = usb.util.get_string(dev, index) if index else ""
                except (usb.core.USBError, ValueError) as exc:
                    if getattr(exc, "errno", None) == 13:
                        raise
                    serial = ""
                found.append({"name": name, "vid": vid, "pid": pid, "bus": dev.bus,
                              "address": dev.address, "serial": serial or "",
                              "firmware": firmware_version(int(getattr(dev, "bcdDevice", 0)))})
    except usb.core.NoBackendError:
        raise LinkError("no USB backend (libusb) found; install it (Debian/Ubuntu: "
                        "sudo apt install libusb-1.0-0) and retry") from None
    except usb.core.USBError as exc:
        if exc.errno == 13:
            raise LinkError(f"no permission to open the Crazyradio; {UDEV_HINT}") from None
        raise LinkError(f"USB error while scanning ({exc}); replug the Crazyradio") from None
    return found


def scan_crazyflies(address: int | None = None) -> list[str]:
    """URIs of the Crazyflies cflib finds on every link driver (radio, USB, UDP, ``sim://``)."""
    import cflib.crtp

    from groundstation.flight.link import install_drivers

    install_drivers()
    uris: list[str] = []
    # cflib.crtp.init_drivers() appends its drivers again on every call (a script or a plugin
    # may have called it too): scan each driver class once and list each URI once
    for driver in dict.fromkeys(cflib.crtp.CLASSES):
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # cflib prints "Cannot find ..."
                found = driver().scan_interface(address) or []
            uris += [u for u in (str(entry[0]) for entry in found) if u not in uris]
        except Exception as exc:  # one driver failing (no dongle) must not hide the others
            log.info("scanning with %s failed: %s", driver.__name__, exc)
    return uris


def _radio_address(text: str) -> int:
    """A radio address: 1 to 10 hex digits (5 bytes at most, ``0x`` allowed); one-line
    ``--address`` error otherwise."""
    digits = text.strip()
    digits = digits[2:] if digits[:2].lower() == "0x" else digits
    if not digits or len(digits) > 10 or any(c not in string.hexdigits for c in digits):
        raise click.BadParameter(f"{text!r} is not a radio address: 1 to 10 hex digits "
                                 "(5 bytes), e.g. E7E7E7E7E7", param_hint="--address")
    return int(digits, 16)


@click.command("scan")
@click.option("--address", default=None, help="Radio address to scan, hex (default E7E7E7E7E7).")
@click.option("--emulated-radio", is_flag=True,
              help="Scan an emulated Crazyradio PA with a simulated Crazyflie on channel 80, "
                   "2M, E7E7E7E7E7 instead of the USB bus (docs/flying.md).")
def command(address: str | None, emulated_radio: bool) -> None:
    """List Crazyradios and Crazyflies.

    \b
    Examples:
      groundstation scan
      groundstation scan --address E7E7E7E7E8
      groundstation scan --emulated-radio
    """
    addr = None if address is None else _radio_address(address)
    if emulated_radio:
        from groundstation.sim.crazyradio_usb import emulated_radio as emulated

        with emulated():
            _scan(addr)
    else:
        _scan(addr)


def _scan(addr: int | None) -> None:
    try:
        devices, problem = find_usb_devices(), ""
    except LinkError as exc:  # still list what other links (sim://, udp://) can reach
        devices, problem = [], str(exc)
    for d in devices:
        serial = f" serial {d['serial']}" if d["serial"] else ""
        firmware = f" firmware {d['firmware']:g}" if d["pid"] == 0x7777 else ""
        click.echo(f"usb {d['vid']:04x}:{d['pid']:04x} {d['name']}{firmware} (bus {d['bus']} "
                   f"address {d['address']}){serial}")
    if not problem and not any(d["pid"] == 0x7777 for d in devices):
        problem = ("no Crazyradio found on USB; plug in a Crazyradio PA (1915:7777), "
                   "or if it is plugged in, " + UDEV_HINT)
    uris = scan_crazyflies(addr)
    for uri in uris:
        click.echo(f"crazyflie {uri}")
    if problem and not uris:  # cflib's UDP scan asks ports 19850-19859 of this host only
        raise LinkError(f"{problem}; no simulator answered either (`groundstation sim` "
                        "answers on ports 19850-19859 of this host; fly one elsewhere, or "
                        "sim://0, by its URI)")
    if problem:
        click.echo(f"warning: {problem}", err=True)
    elif not uris:
        click.echo("no Crazyflie answered; switch it on and check its channel and address",
                   err=True)
