"""The former path of the session writer and reader, kept for callers:
``from groundstation.session import SessionWriter, open_session``.

The session format is now the package :mod:`cfsession` (``writer.py``, ``reader.py``,
``schema.py``, ``errors.py``), which imports neither ``groundstation`` nor ``sysid``; this module
only re-exports the names ``groundstation/session.py`` used to define, the same objects.
"""

from cfsession import Session, SessionWriter, event_rows, open_session, standard_streams

__all__ = ["Session", "SessionWriter", "event_rows", "open_session", "standard_streams"]
