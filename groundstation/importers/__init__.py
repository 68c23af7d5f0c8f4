"""Importers: turn logs written by other tools into arrays and session files.

* :mod:`groundstation.importers.usd` reads the uSD-card deck's binary log format.
* :mod:`groundstation.importers.cfclient_csv` reads the cfclient "log to file" CSVs.
* :mod:`groundstation.importers.to_session` writes either as a session file.
* :mod:`groundstation.importers.airborne` finds the airborne segments (the imported phases).
* :mod:`groundstation.importers.limits` checks variable names and counts.
"""

from groundstation.importers.airborne import Segment, airborne_segments, find_segments
from groundstation.importers.cfclient_csv import CsvFormatError, CsvLog, read_cfclient_csv
from groundstation.importers.to_session import csv_to_session, usd_to_session
from groundstation.importers.usd import UsdEvent, UsdFormatError, UsdLog, read_usd

__all__ = [
    "CsvFormatError",
    "CsvLog",
    "Segment",
    "UsdEvent",
    "UsdFormatError",
    "UsdLog",
    "airborne_segments",
    "csv_to_session",
    "find_segments",
    "read_cfclient_csv",
    "read_usd",
    "usd_to_session",
]
