"""Which log variables a user's channel names select: the one rule of offline identification
(``sysid`` reading a session file) and live identification (``groundstation fly --live-id``,
on the log streams a flight records), so both see the same channels under the same labels.

Each name selects, trying in this order:

1. a log stream (``"motors"``): all its value fields, in field order;
2. ``"stream.field"`` (``"gyro.x"``, ``"motors.m2"``);
3. the firmware variable a field was logged from (``"motor.m4"``, ``"controller.cmd_roll"``,
   matched against :attr:`Field.source`) when exactly one stream logs it;
4. a variable group (``"gyro"``, no dot): every logged ``gyro.*`` variable, when no stream has
   that name, in the order of the streams' names (as a session file lists them, so the flight's
   planned streams and the file read back agree) and then of their fields.

A variable logged in several streams must be named as ``stream.field``. A channel's label is its
firmware variable (``motor.m1``) when exactly one stream logs it, else ``stream.field``. A name
that selects nothing, a variable logged in several streams, no names at all, a label
selected twice, or a field that holds text is a one-line :class:`~cfsession.errors.ChannelError`.

>>> from cfsession.schema import log_block_spec
>>> motors = log_block_spec(name="motors", period_s=0.02,
...                         variables=[(f"motor.m{i}", "uint16_t") for i in (1, 2)])
>>> [c.label for c in resolve_channels(["motors"], streams=[motors], role="input")]
['motor.m1', 'motor.m2']
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from cfsession.errors import ChannelError, did_you_mean, shown_name
from cfsession.reader import Session, StreamData
from cfsession.schema import Field, StreamSpec

__all__ = ["Channel", "ChannelError", "Role", "resolve_channels", "session_specs", "spec_of"]

Role = Literal["input", "output"]
_TIMES = ("host_time", "fw_time_ms")


@dataclass(frozen=True)
class Channel:
    """One selected log variable: stream, field, label (``motor.m1``) and unit."""

    stream: str
    field: str
    label: str
    unit: str


def spec_of(stream: StreamData) -> StreamSpec:
    """The :class:`StreamSpec` of a stream as read: its fields with their units and sources."""
    dtype = stream.data.dtype
    fields = tuple(Field(n, dtype[n].str, stream.units.get(n, ""), stream.sources.get(n, ""))
                   for n in dtype.names or ())
    return StreamSpec(name=stream.name, kind=stream.kind, fields=fields,
                      period_s=stream.period_s, attrs=dict(stream.attrs))


def session_specs(session: Session) -> list[StreamSpec]:
    """The specs of a read session's log streams that hold rows (an empty stream has nothing
    to select)."""
    return [spec_of(s) for s in session.streams.values() if s.kind == "log" and len(s)]


_LISTED = 12
"""Most variables a message lists (an imported uSD log is one stream of dozens)."""


def _variables(by_source: dict[str, list[tuple[str, str]]]) -> str:
    """`` holding variables a, b, ... (N in all)`` for a message: what the streams log, by
    the firmware's names, when the stream names alone do not say it."""
    names = sorted(by_source)
    if not names:
        return ""
    more = f", ... ({len(names)} in all)" if len(names) > _LISTED else ""
    return f" holding variables {', '.join(shown_name(n) for n in names[:_LISTED])}{more}"


def resolve_channels(names: Sequence[str], *, streams: Sequence[StreamSpec],
                     role: Role) -> list[Channel]:
    """The log variables ``names`` select on the log streams among ``streams``, in order
    (module docstring). One-line :class:`ChannelError` without a file name (the caller adds
    its context)."""
    # by name, as a session file lists its streams: a group spanning streams keeps one order
    logs = {s.name: s for s in sorted(streams, key=lambda s: s.name) if s.kind == "log"}
    fields = {n: {f.name: f for f in s.fields if f.name not in _TIMES} for n, s in logs.items()}
    by_source: dict[str, list[tuple[str, str]]] = {}
    for sname, fs in fields.items():
        for f in fs.values():
            if f.source:
                by_source.setdefault(f.source, []).append((sname, f.name))

    def channel(sname: str, fname: str) -> Channel:
        f = fields[sname][fname]
        unique = "." in f.source and len(by_source.get(f.source, [])) == 1
        return Channel(sname, fname, f.source if unique else f"{sname}.{fname}", f.unit)

    out: list[Channel] = []
    for name in names:
        sname, _, fname = name.partition(".")
        if name in fields:
            out += [channel(name, f) for f in fields[name]]
        elif sname in fields and fname in fields[sname]:
            out.append(channel(sname, fname))
        elif len(by_source.get(name, [])) == 1:
            out.append(channel(*by_source[name][0]))
        elif "." not in name and (group := [sf for src, sfs in by_source.items()
                                            if src.startswith(name + ".") for sf in sfs]):
            out += [channel(*sf) for sf in group]
        elif by_source.get(name):
            where = [f"{s}.{f}" for s, f in by_source[name]]
            raise ChannelError(f"{role} {shown_name(name)} is logged in several streams "
                               f"({where}); name one of those", problem="ambiguous", role=role,
                               name=name,
                               logged=tuple(sorted(fields)))
        else:
            known = [*fields, *(f"{sn}.{fn}" for sn, fs in fields.items() for fn in fs),
                     *by_source]
            raise ChannelError(f"no log stream or variable {shown_name(name)} for the {role}s"
                               f"{did_you_mean(name, known)}; log streams are "
                               f"[{', '.join(shown_name(n) for n in sorted(fields))}]"
                               f"{_variables(by_source)} (use STREAM or STREAM.FIELD or "
                               "group.variable)", problem="unknown", role=role, name=name,
                               logged=tuple(sorted(fields)))
    if not out:
        raise ChannelError(f"no {role} channels selected; name at least one", problem="empty",
                           role=role, logged=tuple(sorted(fields)))
    text = [c for c in out if np.dtype(fields[c.stream][c.field].dtype).kind not in "biuf"]
    if text:  # a session field may hold text; a channel is numbers
        c = text[0]
        raise ChannelError(f"{role} {shown_name(c.label)} (field {shown_name(c.field)} of log "
                           f"stream {shown_name(c.stream)}) "
                           f"holds text ({np.dtype(fields[c.stream][c.field].dtype)}), not "
                           "numbers; a channel must hold numbers", problem="text", role=role,
                           name=c.label, logged=tuple(sorted(fields)))
    labels = [c.label for c in out]
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise ChannelError(f"{role} channel(s) {dup} selected twice; name each once",
                           problem="duplicate", role=role, name=", ".join(dup),
                           logged=tuple(sorted(fields)))
    return out
