"""Exception tree of the identification engine.

Every error a user can cause derives from :class:`SysIdError`; each also inherits the closest
built-in (``ValueError``, ``ImportError``, ``OSError``) so callers can catch those as usual.
Messages are one line: they name the offending thing and say what to change.
"""

from __future__ import annotations

__all__ = [
    "ClusterError",
    "DataError",
    "DimensionError",
    "HorizonError",
    "MissingDependencyError",
    "ModelFileError",
    "OrderError",
    "ParameterError",
    "SysIdError",
    "first_line",
]


def first_line(exc: BaseException) -> str:
    """An exception as one line of a report (a failed row, a refusal): its message's first
    line, or its type's name when it has no message."""
    text = str(exc).strip()
    return text.splitlines()[0].strip() if text else type(exc).__name__


class SysIdError(Exception):
    """Base class of every identification error that is meant for the user."""


class DimensionError(SysIdError, ValueError):
    """Arrays of the wrong shape: mismatched lengths, wrong number of channels or states."""


class DataError(SysIdError, ValueError):
    """Unusable data: NaN/inf, too few samples for the horizons, constant channels."""


class HorizonError(SysIdError, ValueError):
    """Past/future horizons that are not positive integers or do not fit the order."""


class OrderError(SysIdError, ValueError):
    """A model order larger than the rank the data and horizons make available."""


class ParameterError(SysIdError, ValueError):
    """An option outside its allowed values (e.g. an unknown method name)."""


class ModelFileError(SysIdError, ValueError):
    """A model file is missing, damaged, of an unknown format or of a newer version."""


class MissingDependencyError(SysIdError, ImportError):
    """An optional package (e.g. python-control) is needed for this call but not installed."""


class ClusterError(SysIdError, RuntimeError):
    """A Dask cluster that cannot do the work: its scheduler cannot be reached, does not speak
    the Dask protocol, has no workers, or was lost during the run (:mod:`sysid.cluster`)."""
