"""Exception tree of the ground station.

Every error a user can cause derives from :class:`GroundStationError`, except the session
format's own :class:`~cfsession.errors.SessionError` (re-exported here); the command line turns
both into one-line messages and exit code 2. Each also inherits the closest built-in so that
callers can catch ``ValueError`` / ``OSError`` as usual.
"""

from __future__ import annotations

from cfsession.errors import SessionError

__all__ = [
    "FlightAborted",
    "GroundStationError",
    "LinkError",
    "PlanError",
    "SessionError",
]


class GroundStationError(Exception):
    """Base class of every ground-station error that is meant for the user."""


class PlanError(GroundStationError, ValueError):
    """A flight plan is malformed or violates the vehicle limits."""


class LinkError(GroundStationError, ConnectionError):
    """The Crazyflie could not be reached, or the link was lost."""


class FlightAborted(GroundStationError, RuntimeError):
    """A flight ended early (Ctrl-C, link loss, limit violation); the motors were stopped."""
