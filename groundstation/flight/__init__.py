"""Flying a plan: the runner and what it needs.

:mod:`~groundstation.flight.runner` (:func:`fly_plan`, the listener protocol),
:mod:`~groundstation.flight.link` (cflib link, TOC checks, log blocks),
:mod:`~groundstation.flight.clock` (flight clocks per URI scheme),
:mod:`~groundstation.flight.realtime` (signal handlers, thread switch interval),
:mod:`~groundstation.flight.result` (:class:`FlightResult`),
:mod:`~groundstation.flight.safety` (:class:`RateLimits`).
"""

from groundstation.flight.runner import (
    FlightListener,
    FlightResult,
    RateLimits,
    block_summary,
    fly_plan,
)

__all__ = ["FlightListener", "FlightResult", "RateLimits", "block_summary", "fly_plan"]
