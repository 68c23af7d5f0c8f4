"""Link URIs: the schemes a flight connects over, checked (form included) before anything is
created or connected, and what to do when a connect fails (one line, from cflib's reason).

``radio://DONGLE/CHANNEL/RATE/ADDRESS`` (Crazyradio), ``usb://N``, ``udp://HOST:PORT``
(``groundstation sim``, the SITL firmware) and the simulator's ``sim://N?options`` (whose options
its driver reads). Any other scheme (cflib's ``tcp://``, ``prrt://`` too) is
refused, as is a URI of a supported scheme that cflib would misread (a ``udp://`` without a port,
``sim://x``).
"""

from __future__ import annotations

import re
from urllib.parse import parse_qsl, urlsplit

from groundstation.errors import LinkError

__all__ = ["DEFAULT_URI", "URI_SCHEMES", "check_uri", "connect_advice"]

DEFAULT_URI = "radio://0/80/2M/E7E7E7E7E7"
URI_SCHEMES = ("radio", "usb", "udp", "sim")
"""The link URI schemes the ground station flies over (cflib's drivers plus the simulator's)."""

_RADIO = re.compile(r"radio://(?P<dongle>[0-9A-Za-z]+)"
                    r"(?:/(?P<channel>[0-9]{1,3})(?:/(?:250K|1M|2M)(?:/[0-9A-Fa-f]{1,10})?)?)?/?"
                    r"(?:\?(?P<query>.*))?")
_USB = re.compile(r"usb://[0-9]{1,3}")
_MAX_CHANNEL = 125


def check_uri(uri: str) -> str:
    """``uri`` if a link driver serves its scheme and cflib reads it as meant; one-line
    :class:`LinkError` saying the form to use otherwise (before anything is created or
    connected)."""
    scheme, sep, _ = uri.partition("://")
    if not sep or scheme not in URI_SCHEMES:
        supported = ", ".join(f"{s}://" for s in URI_SCHEMES)
        raise LinkError(f"cannot connect to {uri}: unknown link URI scheme "
                        f"{scheme + sep if sep else scheme!r}; use one of {supported} (e.g. "
                        f"{DEFAULT_URI}; groundstation scan lists the Crazyflies in reach)")
    problem = {"radio": _radio_problem, "usb": _usb_problem, "udp": _udp_problem,
               "sim": _sim_problem}[scheme](uri)
    if problem:
        raise LinkError(f"cannot connect to {uri}: {problem}")
    return uri


def _radio_problem(uri: str) -> str:
    m = _RADIO.fullmatch(uri)
    query = dict(parse_qsl(m["query"] or "", keep_blank_values=True)) if m else {}
    if (m is None or int(m["channel"] or 0) > _MAX_CHANNEL
            or not query.get("rate_limit", "0").isdigit()):
        return ("not a radio URI; use radio://DONGLE/CHANNEL/RATE/ADDRESS (channel 0-125, rate "
                f"250K, 1M or 2M, address up to 10 hex digits), e.g. {DEFAULT_URI} "
                "(groundstation scan lists the Crazyflies in reach)")
    return ""


def _usb_problem(uri: str) -> str:
    if _USB.fullmatch(uri) is None:
        return "not a USB URI; use usb://N, e.g. usb://0 (groundstation scan lists them)"
    return ""


def _udp_problem(uri: str) -> str:
    parts = urlsplit(uri)
    try:
        port = parts.port
    except ValueError:  # not a number, or beyond 65535
        port = None
    if not parts.hostname or port is None or port == 0 or parts.path.strip("/") \
            or parts.query or parts.fragment or parts.username is not None:
        return ("a udp:// URI is udp://HOST:PORT, e.g. udp://127.0.0.1:19850 (where "
                "groundstation sim listens)")
    return ""


def _sim_problem(uri: str) -> str:
    parts = urlsplit(uri)
    address = (parts.netloc + parts.path).strip("/") or "0"
    if not address.isdigit() or not address.isascii():
        return (f"the simulated vehicle {address!r} is not a number; use sim://N?speed=..., "
                "e.g. sim://0?speed=20")
    return ""  # the options: the sim:// driver reads them, refusing a bad one in one line


def connect_advice(why: str, *, uri: str) -> str:
    """What to do about a failed connect to ``uri``, from cflib's reason."""
    low = why.lower()
    if uri.startswith("udp://"):  # nothing but a simulator or SITL listens there
        parts = urlsplit(uri)
        if any(k in low for k in ("name or service not known", "nodename nor servname",
                                  "name resolution")):
            return (f"the host name {parts.hostname!r} does not resolve; use the address of "
                    f"the computer running the simulator, e.g. udp://127.0.0.1:{parts.port}")
        return (f"check that a simulator or SITL is listening on {parts.hostname}:{parts.port}"
                f" (groundstation sim --port {parts.port}; with --firmware for SITL)")
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
