"""The errors of the session format.

Every problem with a session file (missing, damaged, not a session, of a newer schema, a name
that is not in it) is a :class:`SessionError`: a ``ValueError`` with a one-line message that names
the file and says what to do. Both command lines print it as one line and exit with code 2.
:class:`ChannelError`, a channel name that selects no log variable (or two things, or one
twice), is one of them; its message names no file, so a caller prefixes its own context.
"""

from __future__ import annotations

import difflib
from collections.abc import Sequence
from typing import Literal

__all__ = ["MAX_SHOWN_NAME", "ChannelError", "ChannelProblem", "SessionError", "did_you_mean",
           "shown_name"]

MAX_SHOWN_NAME = 60
"""Characters of a name a message quotes (:func:`shown_name`); a channel name is a few dozen."""

ChannelProblem = Literal["unknown", "ambiguous", "duplicate", "empty", "text"]


class SessionError(ValueError):
    """A session file is missing, damaged, not a session, or of a newer schema."""


class ChannelError(SessionError):
    """Channel names (:func:`cfsession.channels.resolve_channels`) that select no log variable,
    a variable logged in several streams, one twice, nothing at all, or a field of text.

    Attributes:
        problem: which of those (``unknown``, ``ambiguous``, ``duplicate``, ``empty``,
            ``text``).
        role: the role the names were given for (``input``, ``output``).
        name: the offending name ('' for ``empty``; the labels for ``duplicate``).
        logged: the log streams the names were resolved against, sorted.
    """

    def __init__(self, message: str, *, problem: ChannelProblem, role: str, name: str = "",
                 logged: tuple[str, ...] = ()) -> None:
        super().__init__(message)
        self.problem, self.role, self.name, self.logged = problem, role, name, logged


def did_you_mean(name: str, known: Sequence[str]) -> str:
    """`` (did you mean 'x'?)`` for the names of ``known`` closest to ``name`` (case aside);
    ``""`` when none is close."""
    lower = {k.lower(): k for k in known}
    close = [name.lower()] if name.lower() in lower else difflib.get_close_matches(
        name.lower(), list(lower), n=3, cutoff=0.75)
    return f" (did you mean {' or '.join(shown_name(lower[c]) for c in close)}?)" if close else ""


def shown_name(name: str, *, limit: int = MAX_SHOWN_NAME) -> str:
    """``name`` quoted for a message; one longer than ``limit`` characters (a file's name of
    150 000) cut to its first ``limit`` and its length: ``'xxx...'... (150000 characters)``."""
    return repr(name) if len(name) <= limit else f"{name[:limit]!r}... ({len(name)} characters)"
