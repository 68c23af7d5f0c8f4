"""The flight-session file format: one HDF5 file per flight (``docs/session-format.md``).

A standalone package: it imports neither ``groundstation`` nor ``sysid`` nor cflib nor Rerun, so a
session can be read with numpy and h5py alone.

>>> from cfsession import open_session
>>> s = open_session("flight.h5")                                    # doctest: +SKIP
>>> s["gyro"].values().shape                                         # doctest: +SKIP

:mod:`cfsession.schema` (stream kinds, fields, units, version), :mod:`cfsession.writer`
(:class:`SessionWriter`, the only writer; it writes through :mod:`cfsession.diskfile` and
settles the closed file with :mod:`cfsession.saving`), :mod:`cfsession.reader`
(:func:`open_session`, the only reader), :mod:`cfsession.channels` (which log variables channel
names select, for offline and live identification alike), :mod:`cfsession.errors`
(:class:`SessionError`).
"""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("cf-sysid")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

from cfsession.channels import Channel, resolve_channels
from cfsession.errors import ChannelError, SessionError
from cfsession.reader import (
    Event,
    Gap,
    PhaseWindow,
    Session,
    StreamData,
    open_session,
    warn_problems,
)
from cfsession.reader import (
    Stream as Stream,  # the former name of StreamData, kept for callers
)
from cfsession.schema import SCHEMA_NAME, SCHEMA_VERSION, Field, StreamSpec
from cfsession.writer import SessionWriter, event_rows, standard_streams

__all__ = [
    "SCHEMA_NAME",
    "SCHEMA_VERSION",
    "Channel",
    "ChannelError",
    "Event",
    "Field",
    "Gap",
    "PhaseWindow",
    "Session",
    "SessionError",
    "SessionWriter",
    "StreamData",
    "StreamSpec",
    "__version__",
    "event_rows",
    "open_session",
    "resolve_channels",
    "standard_streams",
    "warn_problems",
]
