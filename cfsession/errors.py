"""The one error of the session format.

Every problem with a session file (missing, damaged, not a session, of a newer schema, a name
that is not in it) is a :class:`SessionError`: a ``ValueError`` with a one-line message that names
the file and says what to do. Both command lines print it as one line and exit with code 2.
"""

from __future__ import annotations

__all__ = ["SessionError"]


class SessionError(ValueError):
    """A session file is missing, damaged, not a session, or of a newer schema."""
