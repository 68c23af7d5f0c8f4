"""Importers: turn logs written by other tools into arrays (and later into session files).

* :mod:`groundstation.importers.usd` reads the uSD-card deck's binary log format.
"""

from groundstation.importers.usd import UsdEvent, UsdFormatError, UsdLog, read_usd

__all__ = ["UsdEvent", "UsdFormatError", "UsdLog", "read_usd"]
