"""The one bridge from session files (:mod:`cfsession`) to :class:`~sysid.data.IOData`.

No other ``sysid`` module imports :mod:`cfsession`; none imports :mod:`groundstation`.
:func:`load_session` turns one flight into one uniformly sampled experiment (thesis section 4.3.1):

1. **Channels.** Each name in ``inputs``/``outputs`` selects log variables: a log stream
   (``"motors"``: all its fields), ``"stream.field"`` (``"gyro.x"``), the firmware variable it
   was logged from (``"controller.cmd_roll"``, matched against the stream's ``sources``), or a
   firmware group (``"gyro"``: every logged ``gyro.*`` variable) when no stream has that name.
2. **Times.** Every sample is placed at its firmware time :math:`\\tau` (the log packet's tick,
   unwrapped, in seconds): when the Crazyflie sampled it, free of radio latency.
3. **Clock alignment.** Phases are on the host clock. The offset
   :math:`\\hat c = \\operatorname{median}_i (t^{host}_i - \\tau_i)` over every selected log row is
   robust to latency spikes; a host-time window :math:`[t_0, t_1)` becomes the firmware window
   :math:`[t_0 - \\hat c,\\ t_1 - \\hat c)`. A window that reaches the end of the session
   (the last phase, e.g. an imported log's one phase ``log``; ``T1`` at or after the end)
   runs to the last sample, included, as ``"all"`` does: no next phase owns that instant.
4. **Grid.** The grid period ``dt`` defaults to the logged period of the selected streams
   (the slowest one when they differ). A stream logged faster than the grid is first
   low-passed by the anti-alias filter of ``scipy.signal.decimate`` (Chebyshev I, order 8,
   0.05 dB ripple, cut-off 0.8 of the grid's Nyquist frequency, zero phase) on its own
   samples, and a warning says so; a zero-order hold of a raw 100 Hz signal onto a 50 Hz grid
   would alias everything above 25 Hz into the band.
5. **Zero-order hold** of every channel onto one grid :math:`g_j = \\tau_s + j\\,\\Delta t`
   (:func:`sysid.preprocess.resample_streams`) starting where every channel has a sample,
   then optional mean/linear detrending.

**Windows** (:data:`Window`, :func:`parse_window`): ``"auto"`` is every excitation phase
when the session has one, else every phase named ``airborne-1``, ``airborne-2``, ... (imported logs:
motors on and airborne), each its own experiment (:func:`load_experiments`); a phase name or
kind; ``T0:T1`` host seconds; ``PHASE@T0:T1`` seconds from the start of PHASE (``PHASE@T0:``
to its end); ``"all"``. The result has ``u (N, m)``, ``y (N, l)``, the channel
   names (``"motor.m1"``, ``"gyro.x"``) and units of the session.

Several flights (:func:`load_sessions`) stay separate experiments: never joined end to end.

A damaged or crash-truncated session is read as far as it goes; each of its problems
(:attr:`cfsession.Session.problems`, what ``groundstation info`` lists) is logged as a warning
naming the file by :func:`load_experiments`, which every command and function here reads
sessions through.
"""

from __future__ import annotations

import logging
import math
import os
import re
from collections.abc import Container, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, TypeVar

import numpy as np

from cfsession import Session, open_session, warn_problems
from cfsession.channels import Channel, session_specs
from cfsession.channels import resolve_channels as _resolve
from cfsession.errors import MAX_SHOWN_NAME, ChannelError, SessionError, shown_name
from sysid.data import IOData
from sysid.errors import DataError, ParameterError
from sysid.preprocess import Stream, detrend_data, iodata_from_streams

__all__ = ["AUTO", "MAX_SHOWN_NAME", "Channel", "PhaseRelative", "SessionFileError", "Window",
           "clock_offset", "load_experiments", "load_session", "load_sessions", "parse_window",
           "read_metadata", "resolve_channels", "session_window", "shown_name", "unique_name"]

log = logging.getLogger(__name__)
T = TypeVar("T")

@dataclass(frozen=True)
class PhaseRelative:
    """Seconds ``[t0, t1)`` from the start of the first phase named (or of kind) ``phase``;
    ``t1=None`` runs to that phase's end, and so does a ``t1`` beyond it (cut there, with a
    warning: what follows the phase, a hover, the landing, the next phase of that kind, is not
    in it). ``t0 >= 0``."""

    phase: str
    t0: float
    t1: float | None = None


Window = str | tuple[float, float] | PhaseRelative | None
"""``"auto"``, a phase name or kind, a host-time ``(t0, t1)`` in seconds, a
:class:`PhaseRelative`, or None for the whole log (module docstring). A name or kind is
first to last matching phase, one experiment, except the kind ``airborne`` of an imported
log's segments: each its own experiment, never the ground between them."""

AUTO = "auto"
_AIRBORNE = re.compile(r"airborne-(\d+)")

_DETREND = ("mean", "linear", None)

SessionFileError = SessionError
"""Re-exported: callers of this bridge catch session-file errors without importing cfsession."""


def resolve_channels(session: Session, names: Sequence[str], *,
                     role: Literal["input", "output"]) -> list[Channel]:
    """Log variables selected by ``names`` (module docstring, step 1), in order: the rule of
    :func:`cfsession.channels.resolve_channels` (live identification uses it too) on the
    session's log streams that hold rows. One-line :class:`DataError` naming the file (its
    ``channel`` attribute: the :class:`~cfsession.errors.ChannelError`, for a caller's
    wording)."""
    try:
        return _resolve(names, streams=session_specs(session), role=role)
    except ChannelError as exc:
        err = DataError(f"{session.path}: {exc}")
        err.channel = exc  # type: ignore[attr-defined]
        err.path = session.path  # type: ignore[attr-defined]
        raise err from None


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
    try:
        return Stream(name=ch.label, t=t, values=v, unit=ch.unit)
    except DataError as exc:  # a NaN logged: which of the sessions holds it
        raise DataError(f"{session.path}: {exc}") from None


def parse_window(text: str) -> Window:
    """The command-line form of a window (module docstring): ``auto``, ``all``, a phase,
    ``T0:T1`` or ``PHASE@T0:T1`` (``PHASE@T0:`` to the phase's end)."""
    text = text.strip()
    if text.lower() in ("all", "none", ""):
        return None
    if text.lower() == AUTO:
        return AUTO
    phase, at, span = text.rpartition("@") if "@" in text else ("", "", text)
    if ":" not in span:
        if at:
            raise ParameterError(f"window {text!r}: after '@' give T0:T1 seconds from the "
                                 "phase start")
        return text
    try:
        a, b = span.split(":")
        t0, t1 = float(a), (float(b) if b.strip() or not at else None)
        if not math.isfinite(t0) or (t1 is not None and not math.isfinite(t1)):
            raise ValueError
    except ValueError:
        raise ParameterError(f"window {text!r}: use auto, all, a phase name, T0:T1 (finite "
                             "seconds) or PHASE@T0:T1 (seconds from the phase start)") from None
    if t1 is not None and not t1 > t0:
        raise ParameterError(f"window {text!r} is empty; give T1 > T0")
    if at:
        if not phase:
            raise ParameterError(f"window {text!r}: name the phase before '@'")
        return PhaseRelative(phase=phase, t0=t0, t1=t1)
    return (t0, t1)  # type: ignore[return-value]


def _phase(session: Session, name: str, *, hint: str = "") -> tuple[float, float]:
    try:
        return session.phase_window(name)
    except SessionError as exc:  # names the file and the phases; add what to do
        raise SessionError(f"{exc}; choose one of them, or a time window "
                           f"(CLI: --window NAME | T0:T1 | NAME@T0:T1 seconds | all){hint}"
                           ) from None


def unique_name(base: str, taken: Container[str], *, tried: dict[str, int] | None = None) -> str:
    """``base``, or ``base-2``, ``base-3`` ... the first not in ``taken`` (an experiment's
    label, a batch group named after a file stem). ``tried``, kept across calls while
    ``taken`` only grows, remembers where each base's search stopped: n names of one base cost
    O(n), not O(n^2) (40 000 phases named ``prbs`` in a 2 MB file hung ``sysid`` for ever)."""
    name, k = base, 2 if tried is None else tried.get(base, 2)
    while name in taken:
        name, k = f"{base}-{k}", k + 1
    if tried is not None:
        tried[base] = k
    return name


def host_windows(session: Session, window: Window, *, verb: str = "identify from"
                 ) -> list[tuple[str, tuple[float, float] | None]]:
    """The experiments a window selects: ``(label, host-time (t0, t1) or None)`` each.
    ``verb`` says what they are for in the refusal of an ``"auto"`` window that finds none
    ("no excitation or airborne-N phase to identify from", "... to compare the model on")."""
    if window is None:
        return [("all", None)]
    if isinstance(window, PhaseRelative):
        hits = [p for p in session.phases() if window.phase in (p.name, p.kind)]
        if not hits:
            _phase(session, window.phase)  # the refusal, naming the phases there are
        start, end = hits[0].start_s, hits[0].end_s  # the first one's own, not to the last's end
        label = f"{window.phase}@{window.t0:g}:{'' if window.t1 is None else f'{window.t1:g}'}"
        length = end - start
        if window.t0 < 0:
            raise ParameterError(f"{session.path}: window {label}: T0 is seconds from the phase "
                                 "start, at least "
                                 "0; for time before the phase give T0:T1 seconds of the record "
                                 f"(the phase starts at {start:.2f} s)")
        if window.t0 >= length:
            raise DataError(f"{session.path}: window {label} starts after the phase "
                            f"{window.phase!r} ends (it lasts {length:.2f} s)"
                            + (f"; give T0 < {length:.2f}" if length > 0 else
                               "; choose another phase"))
        t1 = end if window.t1 is None else start + window.t1
        if t1 > end:  # seconds *of the phase*: what lies after it (a hover, the landing) is not
            log.warning("%s: window %s ends %.2f s after the phase %r (it lasts %.2f s): cut "
                        "at its end", session.path, label, t1 - end, window.phase, length)
            t1 = end
        return [(label, (start + window.t0, t1))]
    if isinstance(window, str):
        if window != AUTO:
            hits = [p for p in session.phases() if window in (p.name, p.kind)]
            if len(hits) > 1 and all(_AIRBORNE.fullmatch(p.name) for p in hits):
                # an imported log's segments (kind "airborne"): each its own experiment, as
                # "auto" takes them; first to last would hold the ground between them
                return [(p.name, (p.start_s, p.end_s)) for p in hits]
            return [(window, _phase(session, window))]
        phases = session.phases()
        excited = [p for p in phases if "excitation" in (p.name, p.kind)]
        if excited:  # each its own experiment: a PRBS, the hover after it, then a chirp
            labels: set[str] = set()  # joined held out little but the chirp
            tried: dict[str, int] = {}
            spans = []
            for p in excited:
                label = unique_name(p.name, labels, tried=tried)  # prbs, prbs, prbs-2: NAME-k
                labels.add(label)
                spans.append((label, (p.start_s, p.end_s)))
            return spans
        airborne = [(p.name, (p.start_s, p.end_s)) for p in phases
                    if _AIRBORNE.fullmatch(p.name)]
        if airborne:
            return airborne
        names = sorted({p.name for p in phases})
        raise DataError(f"{session.path}: no excitation or airborne-N phase to {verb} "
                        f"(phases are {names}); pass a window: a phase, T0:T1, NAME@T0:T1 "
                        "seconds or all")
    try:
        t0, t1 = (float(x) for x in window)
    except (TypeError, ValueError):
        raise ParameterError(f"window={window!r}; pass a phase name, (t0, t1) seconds, "
                             "PhaseRelative or None") from None
    if not t1 > t0:
        raise ParameterError(f"window ({t0}, {t1}) s is empty; pass t1 > t0")
    return [(f"{t0:g}:{t1:g}", (t0, t1))]


#: Warn when the grid is this many times finer than the slowest logged stream.
_UPSAMPLE_WARN = 5.0
#: Refuse a grid this many times finer than the slowest logged stream (a typo of dt: 1e-7 s on
#: a 50 Hz log asked for 61 GiB).
_UPSAMPLE_MAX = 1000.0
#: Refuse a grid this many times coarser than the slowest logged stream: it keeps under 1 % of
#: the logged band, and is a unit slip (``--dt 20`` meant 20 ms: 6 samples of a 102 s flight,
#: refused downstream as "too few samples ... looks transposed").
_DOWNSAMPLE_MAX = 100.0
#: Refuse a grid of more values (samples times channels) than this: 2 GiB of float64.
_MAX_GRID_VALUES = 2**28
#: A stream is low-passed before the hold when the grid is this much coarser than its period.
_DECIMATE_FROM = 1.25


def _times(ratio: float) -> str:
    """A ratio for a message: whole up to a million, else three digits (not 300)."""
    return f"{ratio:.0f}" if ratio < 1e6 else f"{ratio:.3g}"


def _stream_period(session: Session, name: str) -> float:
    """Logged period of a stream: its declared period, else the median firmware-time step."""
    st = session[name]
    if st.period_s:
        return float(st.period_s)
    steps = np.diff(st.fw_time_s)
    steps = steps[steps > 0]
    return float(np.median(steps)) if steps.size else 0.0


def _anti_alias(stream: Stream, *, period: float, dt: float) -> Stream:
    """``stream`` low-passed by scipy.signal.decimate's IIR filter for a ``dt / period`` step."""
    import scipy.signal  # where used: scipy.signal takes 0.5 s to import

    sos = scipy.signal.cheby1(8, 0.05, 0.8 * period / dt, output="sos")
    if stream.values.shape[0] <= 3 * (2 * sos.shape[0] + 1):
        log.warning("stream %s: %d samples are too few for the anti-alias filter; held as is",
                    stream.name, stream.values.shape[0])
        return stream
    vals = scipy.signal.sosfiltfilt(sos, stream.values, axis=0)
    return Stream(name=stream.name, t=stream.t, values=vals, unit=stream.unit)


def load_experiments(
    path: str | os.PathLike[str] | Session,
    *,
    inputs: Sequence[str] = ("motors",),
    outputs: Sequence[str] = ("acc", "gyro"),
    window: Window = AUTO,
    dt: float | None = None,
    detrend: str | None = "mean",
    verb: str = "identify from",
) -> list[IOData]:
    """Every experiment ``window`` selects in one session, each an :class:`IOData` on a
    uniform ``dt`` grid (module docstring). ``source`` is the path, with ``#label`` (the
    phase) when the window selects several experiments.

    Args:
        path: the session file (or the :class:`~cfsession.Session` read from it).
        inputs, outputs: channel selections (streams, ``stream.field`` or ``group.variable``).
        window: see :data:`Window`; ``"auto"`` (default) is every excitation phase, else
            every airborne segment, each its own experiment.
        dt: grid period in seconds; None (default) is the logged period of the selected
            streams (the slowest when they differ).
        detrend: ``"mean"``, ``"linear"`` or None, per experiment.
        verb: what the experiments are for, as the refusal of an ``"auto"`` window with
            neither excitation nor airborne phases words it (:func:`host_windows`):
            ``"identify from"`` (default), ``"compare the model on"``, ...
    """
    if detrend not in _DETREND:
        raise ParameterError(f"detrend={detrend!r}; use 'mean', 'linear' or None")
    if dt is not None and not dt > 0:
        raise ParameterError(f"dt={dt}; pass the grid period in seconds (> 0)")
    session = path if isinstance(path, Session) else open_session(path)
    warn_problems(session, log)  # the one place sysid reads sessions: damage is never silent
    summary = session.json_meta("summary", None)
    if isinstance(summary, dict) and summary.get("aborted") is True:
        log.warning("%s: the flight was aborted (%s): its phases end at the abort, and the "
                    "excitation may be shorter than planned", session.path,
                    str(summary.get("cause") or "cause not recorded")[:200])
    ins = resolve_channels(session, inputs, role="input")
    outs = resolve_channels(session, outputs, role="output")
    chans = ins + outs
    untimed = sorted({c.stream for c in chans if session[c.stream].fw_time_s is None})
    if untimed:  # sysid places each sample at its firmware time
        raise DataError(f"{session.path}: log stream(s) {untimed} have no firmware time "
                        "(field 'fw_time_ms'), which places their samples on the grid; "
                        "channels of other streams can be identified from")
    clash = {c.label for c in ins} & {c.label for c in outs}
    if clash:
        raise DataError(f"{session.path}: {sorted(clash)} is both input and output; pick one")
    periods = {c.stream: _stream_period(session, c.stream) for c in chans}
    slowest = max(periods.values())
    if dt is None:
        if not slowest > 0:
            raise DataError(f"{session.path}: the logged period of {sorted(periods)} is "
                            "unknown; pass dt")
        dt = slowest
        log.info("%s: grid dt = %g s, the logged period", session.path, dt)
    if slowest > 0 and dt < slowest / _UPSAMPLE_MAX:
        ratio = slowest / dt
        times = f"{_times(ratio)}x" if math.isfinite(ratio) else "beyond 1e300 times"
        raise ParameterError(f"{session.path}: dt={dt:g} s is {times} finer than the logged "
                             f"period {slowest:g} s; pass dt >= {slowest / _UPSAMPLE_MAX:g} (at "
                             f"most {_UPSAMPLE_MAX:g}x finer)")
    # the grid is on firmware time (whole ms: finite, unlike a damaged host_time of 1e308)
    span = max(float(t[-1] - t[0]) for t in (session[c.stream].fw_time_s for c in chans)
               if t.size) if chans else 0.0
    if span / dt * len(chans) > _MAX_GRID_VALUES:
        raise ParameterError(f"{session.path}: dt={dt:g} s puts {span / dt:.3g} samples of "
                             f"{len(chans)} channels on the grid "
                             f"({span / dt * len(chans) * 8 / 2**30:.3g} GiB over the {span:.3g} s "
                             f"its firmware time spans); pass dt >= "
                             f"{span * len(chans) / _MAX_GRID_VALUES:.2g}")
    offset = clock_offset(session, [c.stream for c in chans])
    streams = [_stream(session, c) for c in chans]
    common = min(s.t[-1] for s in streams) - max(s.t[0] for s in streams)
    if common < dt:  # before the anti-alias filter, whose design fails on such a step
        still = sorted({c.stream for c, s in zip(chans, streams, strict=True)
                        if s.t.size > 1 and not s.t[-1] > s.t[0]})
        if still:  # many rows at one instant: the time stamps are damaged, no dt helps
            raise DataError(f"{session.path}: the firmware time (fw_time_ms) of log stream(s) "
                            f"{still} does not advance over its rows; the file's time stamps "
                            "are damaged")
        if common <= 0:
            spans = {c.stream: (s.t[0], s.t[-1]) for c, s in zip(chans, streams, strict=True)}
            ranges = ", ".join(f"{n} {a:.3f}..{b:.3f} s" for n, (a, b) in spans.items())
            raise DataError(f"{session.path}: the channels' firmware times do not overlap "
                            f"({ranges}); the file's time stamps are damaged or its streams "
                            "are from different flights")
        raise DataError(f"{session.path}: dt={dt:g} s is longer than the {common:.3g} s where "
                        "every channel has data; pass a smaller dt")
    if slowest > 0 and dt > slowest * _DOWNSAMPLE_MAX:
        raise ParameterError(f"{session.path}: dt={dt:g} s is {_times(dt / slowest)}x the "
                             f"logged period {slowest:g} s "
                             f"({1 / slowest:g} Hz); dt is in seconds: pass dt <= "
                             f"{slowest * _DOWNSAMPLE_MAX:g} (at most {_DOWNSAMPLE_MAX:g}x "
                             "coarser), or leave it out for the logged period")
    fast = sorted({c.stream for c in chans if 0 < periods[c.stream] * _DECIMATE_FROM < dt})
    if fast:
        log.warning("%s: %s logged at %s Hz, decimated to the %g Hz grid with an anti-alias "
                    "filter (as scipy.signal.decimate: Chebyshev I order 8, zero phase)",
                    session.path, ", ".join(fast),
                    "/".join(f"{1 / periods[n]:g}" for n in fast), 1 / dt)
        streams = [_anti_alias(st, period=periods[c.stream], dt=dt) if c.stream in fast else st
                   for st, c in zip(streams, chans, strict=True)]
    if slowest > 0 and dt < slowest / _UPSAMPLE_WARN:
        log.warning("%s: dt=%g s is %.0fx finer than the logged period %g s: each sample is "
                    "repeated (zero-order hold) and the horizons count grid steps; pass "
                    "dt >= %g", session.path, dt, slowest / dt, slowest, slowest)
    first = max(s.t[0] for s in streams)
    last = min(s.t[-1] for s in streams)
    spans = host_windows(session, window, verb=verb)
    end = session.duration  # where the last phase ends: no phase starts at that instant
    out = []
    for label, host in spans:
        start, stop = first, last
        if host is not None:
            start = max(first, host[0] - offset)
            if host[1] < end:  # phases are [start, end): the next one owns its first instant
                stop = min(last, host[1] - offset - 1e-6)
        if stop < start + dt:
            span = ("all samples" if host is None else
                    f"window {label} ([{host[0]:.3f}, {host[1]:.3f}) session s)")
            raise DataError(f"{session.path}: {span} holds less than one {dt:g} s step where "
                            f"every channel has data (session seconds {first + offset:.1f} to "
                            f"{last + offset:.1f}); pick a window within them")
        source = str(session.path) if len(spans) == 1 else f"{session.path}#{label}"
        data = iodata_from_streams(
            streams=streams, inputs=[c.label for c in ins], outputs=[c.label for c in outs],
            dt=dt, start=start, stop=stop, max_hold=3.0 * max(dt, slowest), source=source)
        if detrend is not None:
            data, _ = detrend_data(data, kind=detrend)
        log.info("%s [%s]: %d samples, firmware window [%.3f, %.3f] s, host - firmware %.4f s",
                 session.path, label, data.n_samples, start, stop, offset)
        out.append(data)
    return out


def load_session(
    path: str | os.PathLike[str],
    *,
    inputs: Sequence[str] = ("motors",),
    outputs: Sequence[str] = ("acc", "gyro"),
    window: Window = "excitation",
    dt: float | None = 0.02,
    detrend: str | None = "mean",
) -> IOData:
    """One flight as one :class:`IOData` (:func:`load_experiments` with a window that selects
    a single experiment; ``dt=None`` is the logged period).

    Returns:
        ``IOData`` with ``u (N, m)``, ``y (N, l)``, names, units and ``source`` = the path.
    """
    exps = load_experiments(path, inputs=inputs, outputs=outputs, window=window, dt=dt,
                            detrend=detrend)
    if len(exps) > 1:
        raise DataError(f"{path}: window {window!r} selects {len(exps)} experiments "
                        f"({[e.source for e in exps]}); use load_experiments")
    return exps[0]


def read_metadata(path: str | os.PathLike[str]) -> dict[str, Any]:
    """A session's root attributes (``uri``, ``plan_name``, ``start_time_iso``, ...)."""
    return dict(open_session(path).meta)


def session_window(path: str | os.PathLike[str], windows: Mapping[str, T], default: T) -> T:
    """``path``'s own entry of ``windows`` (keyed by a session's path as given, or its file
    name: the path's first), else ``default``: whose window a session is read with."""
    return windows.get(str(path), windows.get(Path(path).name, default))


def load_sessions(paths: Sequence[str | os.PathLike[str]], *,
                  windows: dict[str, Window] | None = None,
                  elsewhere: Sequence[str | os.PathLike[str]] = (),
                  **kwargs: Any) -> list[list[IOData]]:
    """The experiments of each session (:func:`load_experiments`; never joined end to end),
    one list per session, all on one grid period: with ``dt`` None, the first session's
    logged period when every session's is within :data:`PERIOD_MATCH` of it (else one-line
    :class:`~sysid.errors.DataError`). ``windows`` maps a session (its path as given, or its
    file name) to its own window; the others use ``window``. ``elsewhere``: the caller's other
    sessions, read by another call (validation sessions beside the identification ones), whose
    windows ``windows`` may hold too; a window for a session in neither is refused. Other
    ``kwargs`` as :func:`load_experiments`."""
    if not paths:
        raise DataError("no session files given; pass at least one")
    windows = dict(windows or {})
    every = [*paths, *elsewhere]
    unknown = sorted(set(windows) - {str(p) for p in every} - {Path(p).name for p in every})
    if unknown:
        raise ParameterError(f"window for {unknown}: no such session among "
                             f"{[str(p) for p in every]}")
    for p in every:
        if str(p) != Path(p).name and str(p) in windows and Path(p).name in windows:
            raise ParameterError(f"two windows for session {p}: one given for its path, one "
                                 f"for its name {Path(p).name!r}; give one")
    out: list[list[IOData]] = []
    for p in paths:
        own = {**kwargs, "window": session_window(p, windows, kwargs.get("window", AUTO))}
        if out and own.get("dt") is None:  # the first session's grid, when the periods match
            session = open_session(p)
            own["dt"] = _first_period(session, first=(paths[0], out[0][0].dt), **own)
            p = session
        out.append(load_experiments(p, **own))
    return out


PERIOD_MATCH = 0.01
"""Sessions whose logged periods differ by at most this fraction are gridded at one period,
the first session's (two vehicles' clocks, or a period measured from each log's timestamps,
differ by parts per million; each session is resampled on its own timestamps, so that is
exact). Beyond it a grid period must be given."""


def _first_period(session: Session, *, first: tuple[str | os.PathLike[str], float],
                  inputs: Sequence[str] = ("motors",), outputs: Sequence[str] = ("acc", "gyro"),
                  **_: Any) -> float | None:
    """The grid period for ``session`` read after the ``first`` session (its path and period):
    that period when ``session``'s logged period (of the channels selected) is within
    :data:`PERIOD_MATCH` of it; else one-line :class:`~sysid.errors.DataError` naming both.
    None (its own, as :func:`load_experiments` then says why) when the channels do not
    resolve or the period is unknown."""
    try:
        chans = [*resolve_channels(session, inputs, role="input"),
                 *resolve_channels(session, outputs, role="output")]
    except DataError:
        return None
    own = max((_stream_period(session, c.stream) for c in chans), default=0.0)
    path, dt = first
    if not own > 0 or abs(own - dt) <= 1e-9 * dt:
        return None
    if max(own, dt) > (1 + PERIOD_MATCH) * min(own, dt):
        raise DataError(f"the sessions are logged at different periods ({Path(path).name} "
                        f"{dt:g} s, {session.path.name} {own:g} s); pass one grid period for "
                        "all (dt= in Python, --dt on the command line)")
    log.info("%s: logged period %g s, gridded at the first session's %g s", session.path, own,
             dt)
    return dt

