"""cflib's link drivers as the ground station uses them: cflib's own, ``sim://``, and a UDP
driver that resends.

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
"""

from __future__ import annotations

import threading
from typing import Any

__all__ = ["install_drivers", "resending_udp_driver"]

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
