"""cflib's link drivers as the ground station uses them (cflib's own, ``sim://``, and a UDP
driver that resends) and the folder where cflib caches the firmware's TOCs.

cflib resends a request whose answer does not come within 0.2 s (TOC and parameter reads,
parameter writes, log-block commands) only on links whose driver sets ``needs_resending``; its
radio and USB drivers do, its :class:`~cflib.crtp.udpdriver.UdpDriver` does not, as if a
datagram were never lost. One lost request is then a connection that waits for ever. Datagrams
are lost: on a network, and on this machine when a receive buffer overflows or the real
firmware in the loop drops a packet (its socket link hands datagrams to a 5-deep queue without
waiting, ``src/hal/src/socketlink.c``). :func:`resending_udp_driver` is cflib's UDP driver with
cflib's resending switched on, put in its place for ``udp://`` URIs. Setpoints and log packets
expect no answer and are never resent; an answer that was only late arrives twice, which
cflib's TOC, parameter and log code ignore as they do on the radio.

:func:`toc_cache_dir` is where cflib keeps the log and parameter TOCs it fetched, one JSON file
per TOC checksum (as cfclient does): a second connect to the same firmware reads only the
parameter values (0.7 s instead of 1.9 s against the firmware in the loop). A firmware with
another TOC has another checksum and is fetched again; a damaged file is removed and fetched
again.
``GROUNDSTATION_TOC_CACHE`` names another folder, or ``off``. cflib's reader evaluates each
element's ``__class__`` text as Python, so a cache file whose elements are not plainly cflib's
TOC elements is removed before cflib can read it (:func:`toc_cache_dir`).
"""

from __future__ import annotations

import json
import logging
import os
import threading
from pathlib import Path
from typing import Any

__all__ = ["TOC_CACHE_ENV", "install_drivers", "resending_udp_driver", "toc_cache_dir"]

log = logging.getLogger(__name__)

TOC_CACHE_ENV = "GROUNDSTATION_TOC_CACHE"

_lock = threading.Lock()
_ready = False
_resending: type | None = None


def resending_udp_driver() -> type:
    """cflib's ``udp://`` driver class with cflib resending unanswered requests as on the radio
    (made on first use: cflib is imported lazily)."""
    global _resending
    if _resending is None:
        from cflib.crtp.udpdriver import UdpDriver

        class ResendingUdpDriver(UdpDriver):
            """cflib's UDP driver with ``needs_resending`` set (module docstring)."""

            def __init__(self) -> None:
                super().__init__()
                self.needs_resending = True

        _resending = ResendingUdpDriver
    return _resending


def install_drivers() -> None:
    """cflib's link drivers, the simulator's ``sim://`` and :func:`resending_udp_driver` in place
    of cflib's UDP driver (idempotent; cflib's modules are not patched)."""
    global _ready
    with _lock:
        if _ready:
            return
        import cflib.crtp
        from cflib.crtp.udpdriver import UdpDriver

        import groundstation.sim  # the simulated Crazyflie is one more link driver

        if not cflib.crtp.CLASSES:
            cflib.crtp.init_drivers()
        groundstation.sim.install()
        resending: Any = resending_udp_driver()
        classes = cflib.crtp.CLASSES
        classes[:] = [resending if c is UdpDriver else c for c in classes]
        if resending not in classes:
            classes.append(resending)
        _ready = True


def toc_cache_dir() -> Path | None:
    """The TOC cache folder (created if missing): ``$GROUNDSTATION_TOC_CACHE``, else
    ``$XDG_CACHE_HOME/groundstation/toc`` (``~/.cache/...``); None when it is ``off``, empty,
    or cannot be created (then every connect fetches the TOCs)."""
    env = os.environ.get(TOC_CACHE_ENV)
    if env is not None:
        if env.strip().lower() in ("", "off", "0", "no", "none"):
            return None
        folder = Path(env).expanduser()
    else:
        base = os.environ.get("XDG_CACHE_HOME")
        if not base:
            try:
                base = str(Path.home() / ".cache")
            except RuntimeError:  # no home folder
                return None
        folder = Path(base) / "groundstation" / "toc"
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        log.debug("no TOC cache at %s: %s", folder, exc)
        return None
    if not os.access(folder, os.W_OK):
        return None
    for path in folder.glob("*.json"):
        if not _plain_toc_file(path):
            log.warning("removing %s from the TOC cache: not a TOC cflib wrote", path.name)
            try:
                path.unlink()
            except OSError:
                return None  # a file cflib would evaluate stays: no cache
    return folder


_TOC_CLASSES = {"LogTocElement", "ParamTocElement"}
_TOC_FIELDS = {"__class__", "ident", "group", "name", "ctype", "pytype", "access", "extended"}


def _plain_toc_file(path: Path) -> bool:
    """Whether ``path`` is JSON whose every object with a ``__class__`` is a cflib TOC element
    of plain values (what cflib's cache writes). Damaged JSON is not: cflib's decoder evaluates
    each object as it is parsed, before the damage further on is found."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):  # UnicodeDecodeError is a ValueError
        return False

    def plain(obj: Any) -> bool:
        if isinstance(obj, dict):
            if "__class__" in obj:
                return (obj["__class__"] in _TOC_CLASSES and set(obj) <= _TOC_FIELDS
                        and all(isinstance(v, str | int | float | bool | None)
                                for v in obj.values()))
            return all(plain(v) for v in obj.values())
        if isinstance(obj, list):
            return all(plain(v) for v in obj)
        return True

    return plain(data)
