"""Link URIs: the schemes a flight connects over, checked before anything is created or
connected, and what to do when a connect fails (one line, from cflib's reason).

``radio://`` (Crazyradio), ``usb://``, ``udp://`` and the simulator's ``sim://`` (whose driver
reads its options); cflib's ``tcp://`` and ``prrt://`` are accepted but not advertised.
"""

from __future__ import annotations

from groundstation.errors import LinkError

__all__ = ["DEFAULT_URI", "URI_SCHEMES", "check_uri", "connect_advice"]

DEFAULT_URI = "radio://0/80/2M/E7E7E7E7E7"
URI_SCHEMES = ("radio", "usb", "udp", "sim")
"""The link URI schemes the ground station flies over (cflib's drivers plus the simulator's)."""
_OTHER_SCHEMES = ("tcp", "prrt")  # cflib has drivers for these too; rarely used, not advertised


def check_uri(uri: str) -> str:
    """``uri`` if its scheme is one a link driver serves; one-line :class:`LinkError` naming the
    supported schemes otherwise (checked before anything is created or connected)."""
    scheme, sep, _ = uri.partition("://")
    if not sep or scheme.lower() not in (*URI_SCHEMES, *_OTHER_SCHEMES):
        supported = ", ".join(f"{s}://" for s in URI_SCHEMES)
        raise LinkError(f"cannot connect to {uri}: unknown link URI scheme "
                        f"{scheme + sep if sep else scheme!r}; use one of {supported} (e.g. "
                        f"{DEFAULT_URI}; groundstation scan lists the Crazyflies in reach)")
    return uri


def connect_advice(why: str) -> str:
    """What to do about a failed connect, from cflib's reason."""
    low = why.lower()
    if "malformed uri" in low:
        return (f"check the URI's form, e.g. {DEFAULT_URI}, usb://0, udp://127.0.0.1:19850 "
                "or sim://0?speed=20")
    if "crazyradio" in low or "dongle" in low:
        return ("plug in the Crazyradio (groundstation scan lists radios; on Linux without "
                "permission see the udev rule in docs/flying.md)")
    if "too many packets lost" in low:  # the radio's acks never came: nobody on that channel
        return ("no Crazyflie acknowledges on that channel, data rate and address: check it is "
                "on, and run groundstation scan to find its URI")
    if "access denied" in low or "permission" in low or "errno 13" in low:
        return "no USB permission: install the udev rule in docs/flying.md and replug"
    return ("check that the Crazyflie is on, the channel/address in the URI are right "
            "(groundstation scan lists them) and nothing else is connected to it")
