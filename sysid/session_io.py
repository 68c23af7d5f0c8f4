"""The one bridge from ground-station session files to :class:`~sysid.data.IOData`.

No other ``sysid`` module imports :mod:`groundstation`. :func:`load_session` turns one flight
into one uniformly sampled experiment (thesis section 4.3.1):

1. **Channels.** Each name in ``inputs``/``outputs`` selects log variables: a log stream
   (``"motors"``: all its fields), ``"stream.field"`` (``"gyro.x"``), the firmware variable it
   was logged from (``"controller.cmd_roll"``, matched against the stream's ``sources``), or a
   firmware group (``"gyro"``: every logged ``gyro.*`` variable) when no stream has that name.
2. **Times.** Every sample is placed at its firmware time :math:`\\tau` (the log packet's tick,
   unwrapped, in seconds): when the Crazyflie sampled it, free of radio latency.
3. **Clock alignment.** Phases are on the host clock. The offset
   :math:`\\hat c = \\operatorname{median}_i (t^{host}_i - \\tau_i)` over every selected log row is
   robust to latency spikes; a host-time window :math:`[t_0, t_1)` becomes the firmware window
   :math:`[t_0 - \\hat c,\\ t_1 - \\hat c)`.
4. **Zero-order hold** of every channel onto one grid :math:`g_j = \\tau_s + j\\,\\Delta t`
   (:func:`sysid.preprocess.resample_streams`) starting where every channel has a sample,
   then optional mean/linear detrending. The result has ``u (N, m)``, ``y (N, l)``, the channel
   names (``"motor.m1"``, ``"gyro.x"``) and units of the session.

Several flights (:func:`load_sessions`) stay separate experiments: never joined end to end.
"""

from __future__ import annotations

import dataclasses
import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from groundstation.errors import SessionError
from groundstation.session import Session, open_session
from sysid.data import IOData
from sysid.errors import DataError, ParameterError
from sysid.preprocess import Stream, detrend_data, iodata_from_streams

__all__ = ["Channel", "SessionFileError", "Window", "clock_offset", "load_session",
           "load_sessions", "resolve_channels"]

log = logging.getLogger(__name__)

Window = str | tuple[float, float] | None
"""A phase name or kind, a host-time ``(t0, t1)`` in seconds, or None for the whole log."""

_DETREND = ("mean", "linear", None)

SessionFileError = SessionError
"""Re-exported: callers of this bridge catch session-file errors without importing groundstation."""


@dataclass(frozen=True)
class Channel:
    """One selected log variable: stream, field, label (IOData name) and unit."""

    stream: str
    field: str
    label: str
    unit: str


def _log_streams(session: Session) -> dict:
    return {n: s for n, s in session.streams.items() if s.kind == "log" and len(s)}


def resolve_channels(session: Session, names: Sequence[str], *, role: str) -> list[Channel]:
    """Log variables selected by ``names`` (module docstring, step 1), in order.

    The label is the firmware variable (``motor.m1``) when the session records one that is
    unique, else ``stream.field``. One-line :class:`DataError` naming the file for a name that
    matches nothing or a firmware variable logged in more than one stream.
    """
    streams = _log_streams(session)
    by_source: dict[str, list[tuple[str, str]]] = {}
    for sname, st in streams.items():
        for f in st.value_fields:
            by_source.setdefault(st.sources.get(f, ""), []).append((sname, f))

    def channel(sname: str, f: str) -> Channel:
        st = streams[sname]
        src = st.sources.get(f, "")
        label = src if src and "." in src and len(by_source.get(src, [])) == 1 else f"{sname}.{f}"
        return Channel(sname, f, label, st.units.get(f, ""))

    out: list[Channel] = []
    for name in names:
        sname, _, fname = name.partition(".")
        if name in streams:
            out += [channel(name, f) for f in streams[name].value_fields]
        elif sname in streams and fname in streams[sname].value_fields:
            out.append(channel(sname, fname))
        elif len(by_source.get(name, [])) == 1:
            out.append(channel(*by_source[name][0]))
        elif "." not in name and (group := [sf for src, sfs in by_source.items()
                                            if src.startswith(name + ".") for sf in sfs]):
            out += [channel(*sf) for sf in group]
        elif by_source.get(name):
            where = [f"{s}.{f}" for s, f in by_source[name]]
            raise DataError(f"{session.path}: {role} {name!r} is logged in several streams "
                            f"({where}); name one of those")
        else:
            raise DataError(f"{session.path}: no log stream or variable {name!r} for the "
                            f"{role}s; log streams are {sorted(streams)} (use STREAM or "
                            "STREAM.FIELD or group.variable)")
    if not out:
        raise DataError(f"{session.path}: no {role} channels selected; name at least one")
    labels = [c.label for c in out]
    dup = sorted({x for x in labels if labels.count(x) > 1})
    if dup:
        raise DataError(f"{session.path}: {role} channel(s) {dup} selected twice; name each once")
    return out


def clock_offset(session: Session, stream_names: Sequence[str]) -> float:
    """Median of ``host_time - fw_time`` over the rows of the named log streams, seconds."""
    diffs = [session[n].time - session[n].fw_time_s for n in dict.fromkeys(stream_names)]
    return float(np.median(np.concatenate(diffs)))


def _stream(session: Session, ch: Channel) -> Stream:
    st = session[ch.stream]
    t = st.fw_time_s
    v = st.data[ch.field].astype(np.float64)
    if np.any(np.diff(t) < 0):  # out-of-order rows (should not happen): sort, keep order of ties
        log.warning("%s: stream %r rows are out of firmware-time order; sorted",
                    session.path, ch.stream)
        order = np.argsort(t, kind="stable")
        t, v = t[order], v[order]
    return Stream(name=ch.label, t=t, values=v, unit=ch.unit)


def _host_window(session: Session, window: Window) -> tuple[float, float] | None:
    if window is None:
        return None
    if isinstance(window, str):
        try:
            return session.phase_window(window)
        except SessionError as exc:  # names the file and the phases; add what to do
            raise SessionError(f"{exc}; choose one of them, or a time window "
                               "(CLI: --window NAME | T0:T1 seconds | all)") from None
    try:
        t0, t1 = (float(x) for x in window)
    except (TypeError, ValueError):
        raise ParameterError(f"window={window!r}; pass a phase name, (t0, t1) seconds or None")\
            from None
    if not t1 > t0:
        raise ParameterError(f"window ({t0}, {t1}) s is empty; pass t1 > t0")
    return t0, t1


#: Warn when the grid is this many times finer than the slowest logged stream.
_UPSAMPLE_WARN = 5.0


def load_session(
    path: str | os.PathLike[str],
    *,
    inputs: Sequence[str] = ("motors",),
    outputs: Sequence[str] = ("acc", "gyro"),
    window: Window = "excitation",
    dt: float = 0.02,
    detrend: str | None = "mean",
) -> IOData:
    """One flight as an :class:`IOData` on a uniform ``dt`` grid (module docstring).

    Args:
        path: the session file.
        inputs, outputs: channel selections (streams, ``stream.field`` or ``group.variable``).
        window: phase name or kind (first to last matching phase), host-time ``(t0, t1)`` in
            seconds (the clock of the phases), or None for all samples.
        dt: grid period in seconds (50 Hz by default, as the thesis).
        detrend: ``"mean"``, ``"linear"`` or None.

    Returns:
        ``IOData`` with ``u (N, m)``, ``y (N, l)``, names, units and ``source`` = the path.
    """
    if detrend not in _DETREND:
        raise ParameterError(f"detrend={detrend!r}; use 'mean', 'linear' or None")
    if not dt > 0:
        raise ParameterError(f"dt={dt}; pass the grid period in seconds (> 0)")
    session = open_session(path)
    ins = resolve_channels(session, inputs, role="input")
    outs = resolve_channels(session, outputs, role="output")
    chans = ins + outs
    clash = {c.label for c in ins} & {c.label for c in outs}
    if clash:
        raise DataError(f"{session.path}: {sorted(clash)} is both input and output; pick one")
    offset = clock_offset(session, [c.stream for c in chans])
    streams = [_stream(session, c) for c in chans]
    first = max(s.t[0] for s in streams)
    last = min(s.t[-1] for s in streams)
    host = _host_window(session, window)
    start, stop = first, last
    if host is not None:
        start = max(first, host[0] - offset)
        stop = min(last, host[1] - offset - 1e-6)  # phases are [start, end)
    if stop < start + dt:
        span = "all samples" if host is None else f"host window [{host[0]:.3f}, {host[1]:.3f}) s"
        raise DataError(f"{session.path}: {span} holds less than one {dt} s step where every "
                        f"channel has data; pick another window")
    period = max((session[c.stream].period_s or 0.0) for c in chans)
    if period > 0 and dt < period / _UPSAMPLE_WARN:
        log.warning("%s: dt=%g s is %.0fx finer than the logged period %g s: each sample is "
                    "repeated (zero-order hold) and the horizons count grid steps; pass "
                    "dt >= %g", session.path, dt, period / dt, period, period)
    data = iodata_from_streams(
        streams=streams, inputs=[c.label for c in ins], outputs=[c.label for c in outs],
        dt=dt, start=start, stop=stop, max_hold=3.0 * max(dt, period))
    if detrend is not None:
        data, _ = detrend_data(data, kind=detrend)
    log.info("%s: %d samples, firmware window [%.3f, %.3f] s, host - firmware %.4f s",
             session.path, data.n_samples, start, stop, offset)
    return dataclasses.replace(data, source=str(Path(path)))


def load_sessions(paths: Sequence[str | os.PathLike[str]], **kwargs: object) -> list[IOData]:
    """Each session as its own experiment (never joined end to end); ``kwargs`` as
    :func:`load_session`."""
    if not paths:
        raise DataError("no session files given; pass at least one")
    return [load_session(p, **kwargs) for p in paths]

