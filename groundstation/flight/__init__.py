"""Flying a plan: the runner and what it needs.

:mod:`~groundstation.flight.runner` (:func:`fly_plan`, the listener protocol) and the parts it
drives: :mod:`~groundstation.flight.telemetry` (what comes back, watched),
:mod:`~groundstation.flight.commander` (setpoints out, landing, abort, the stop),
:mod:`~groundstation.flight.journal` (rows, events, causes to the listeners),
:mod:`~groundstation.flight.link` (cflib link), :mod:`~groundstation.flight.blocks` (log blocks,
TOC checks), :mod:`~groundstation.flight.uri` (link URIs),
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
