"""The flight view in Rerun: live flights, replayed sessions and plans look the same.

With its layout (:mod:`groundstation.live_layout`), the only module of :mod:`groundstation`
that talks to Rerun. :func:`open_view` returns a :class:`RerunView`, a listener on the flight
runner (:class:`FlightListener`): ``begin`` with the session's stream specs, ``rows`` as they
arrive, ``end`` with the summary. ``groundstation replay`` feeds a recorded session through
the same view with :meth:`RerunView.send_block`.

Entities (one scalar series per entity; labels carry the unit, e.g. ``x [deg/s]``; paths are
built from the names by :func:`cfcommon.rerun.entity_path`, escaped, so an imported stream
``stateEstimate+controller`` is ``/stateEstimate\\+controller/<field>``):

==============================  ============================================================
``/<log stream>/<field>``       every logged variable: ``/motors/m1`` (PWM), ``/acc/x`` (g),
                                ``/gyro/z`` (deg/s), ``/attitude/roll`` (deg), ...
``/setpoints/<axis>``           ``roll``, ``pitch`` (deg), ``yaw_rate`` (deg/s), ``thrust`` (PWM)
``/link/quality``, ``latency``  link quality (%) and round-trip latency (ms); NaN samples skipped
``/phase``                      state (``name (kind)``) and a text line at each phase start
``/events``                     text log ``[source] text`` with the event's level
``/session``                    metadata (plan, URI, firmware, start) and, at the end, summary
==============================  ============================================================

Timelines: ``host_time`` (the flight clock, s, every stream) and, for log streams, ``fw_time``
(the Crazyflie tick, s, 24-bit wraps undone). The default layout (blueprint,
:func:`groundstation.live_layout.flight_blueprint`) plots each log stream in panels of one unit
with short titles and no legend: channel colours are fixed, 1st red, 2nd green, 3rd blue, 4th
orange, and a setpoint is the lighter colour of the axis it commands; hovering a line names it.

Cost: ``rows`` only appends to a queue (about a microsecond, never blocks); a worker thread
converts queued rows to arrays every ``flush_interval`` seconds and sends one
``send_columns`` per channel.
"""

from __future__ import annotations

import json
import logging
import threading
from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import rerun as rr

from cfcommon.rerun import (
    MODES,
    WEB_PORT,
    RecordingFileError,
    ViewModeError,
    close_file,
    entity_path,
    open_recording,
)
from cfsession.schema import StreamSpec, phases_spec, setpoints_spec
from groundstation.errors import GroundStationError
from groundstation.flight.runner import FlightListener  # the runner's listener protocol
from groundstation.live_layout import EVENTS, PHASE, SESSION, flight_blueprint, series_fields
from groundstation.plan.schedule import Schedule

__all__ = [
    "MODES",
    "FlightListener",
    "RerunView",
    "ViewError",
    "flight_blueprint",
    "open_view",
    "plot_plan",
]

log = logging.getLogger(__name__)

_WRAP = 1 << 24  # log packets carry a 24-bit millisecond tick
_LEVELS = {1: "DEBUG", 2: "INFO", 3: "WARN", 4: "ERROR", 5: "CRITICAL"}
#: The fields each special stream kind is drawn from (a stream lacking one is not shown).
_KIND_FIELDS = {"events": ("level", "source", "text", "cont"),
                "phases": ("phase_id", "name", "kind"), "live_id": ("order",)}
#: Largest time Rerun's int64-nanosecond time columns hold, with margin (s).
MAX_TIME_S = 9e9


def _timed(t: np.ndarray) -> np.ndarray:
    """Which of the times ``t`` (s) a Rerun time column takes: finite and within
    :data:`MAX_TIME_S` (one that is not made Rerun drop the whole block, with its own
    warning)."""
    return np.isfinite(t) & (np.abs(t) < MAX_TIME_S)


def _warn_untimed(timed: np.ndarray, name: str) -> bool:
    """True when every row is ``timed``; else a warning that the others are not shown."""
    if timed.all():
        return True
    log.warning("%d row(s) of %s have no usable time (not finite, or beyond %g s): not shown",
                int((~timed).sum()), name, MAX_TIME_S)
    return False
_PALETTE = ((228, 26, 28), (77, 175, 74), (55, 126, 184), (255, 127, 0), (152, 78, 163),
            (0, 190, 190))
_SETPOINT_COLORS = {"roll": (251, 154, 153), "pitch": (178, 223, 138),
                    "yaw_rate": (166, 206, 227), "thrust": (253, 191, 111)}
_META_KEYS = ("plan_name", "tag", "uri", "firmware", "protocol_version", "start_time_iso",
              "software_version", "closed_cleanly", "duration_s")


class ViewError(GroundStationError, ValueError):
    """The view cannot be opened as asked (unknown mode, no .rrd path for mode 'save')."""


@dataclass(frozen=True)
class _Channels:
    """How one stream is shown: numeric ``(field, entity)`` pairs (every other field, and the
    fields of events and phases, are not series), and whether it has a firmware tick."""

    spec: StreamSpec
    channels: tuple[tuple[str, str], ...]
    firmware_time: bool


def _channels(spec: StreamSpec) -> _Channels:
    numeric = tuple((f.name, entity_path(spec.name, f.name)) for f in series_fields(spec))
    return _Channels(spec, numeric, any(f.name == "fw_time_ms" for f in spec.fields))


def _label(field: str, unit: str) -> str:
    return f"{field} [{unit}]" if unit else field


def _series_color(spec: StreamSpec, field: str, index: int) -> tuple[int, int, int]:
    """A fixed colour per channel: 1st red, 2nd green, 3rd blue, 4th orange ...; a setpoint
    takes the lighter colour of the axis it commands (roll red, pitch green, yaw rate blue)."""
    if spec.kind == "setpoints":
        return _SETPOINT_COLORS.get(field, _PALETTE[3])
    return _PALETTE[index % len(_PALETTE)]


class RerunView:
    """A :class:`FlightListener` drawing into a Rerun recording (module docstring).

    ``rows`` queues; a daemon thread sends every ``flush_interval`` seconds (``background``;
    without it, rows are sent when :meth:`flush` or :meth:`end` is called). More than
    ``max_pending_rows`` queued rows (viewer far behind) are dropped and counted in
    ``dropped_rows``, never blocking the caller. ``sent_rows`` counts the rows shown per stream,
    ``untimed_rows`` those left out for want of a usable time (each block with any says so in a
    warning). ``url`` is the web viewer's address (serve);
    ``rrd_path`` the file of mode ``save``, closed by :meth:`end` (a failed write is a one-line
    :class:`ViewError`, the cut-short file removed).
    """

    def __init__(self, *, rec: rr.RecordingStream, url: str | None = None,
                 rrd_path: Path | None = None, flush_interval: float = 0.1,
                 max_pending_rows: int = 200_000, background: bool = True) -> None:
        self.rec = rec
        self.url = url
        self.rrd_path = rrd_path
        self.flush_interval = flush_interval
        self.max_pending_rows = max_pending_rows
        self.background = background
        self.dropped_rows = 0
        self.sent_rows: dict[str, int] = {}  # rows shown, per stream
        self.untimed_rows: dict[str, int] = {}  # rows not shown: no usable time (a warning each)
        self._pending: deque[tuple[str, list[tuple]]] = deque()
        self._n_queued = 0  # rows queued (written by the caller of rows() only)
        self._n_taken = 0  # rows taken off the queue (written by flush() only): no lock needed
        self._lock = threading.Lock()  # send calls and the continued-event state
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._streams: dict[str, _Channels] = {}
        self._metadata: dict[str, Any] = {}
        self._fw_state: dict[str, tuple[int, int]] = {}  # stream -> (last raw ms, wraps)
        self._last_event: tuple[float, str, str, bytes] | None = None
        self._warned: set[str] = set()

    # ------------------------------------------------------------------ listener
    def begin(self, *, streams: Sequence[StreamSpec], metadata: Mapping[str, Any]) -> None:
        """Declare the streams, log the metadata, send the layout, start the worker."""
        self._streams = {s.name: _channels(s) for s in streams}
        self._metadata = dict(metadata)
        for ch in self._streams.values():
            units = {f.name: f.unit for f in ch.spec.fields}
            for i, (field, entity) in enumerate(ch.channels):
                self.rec.log(entity, rr.SeriesLines(names=_label(field, units[field]),
                                                    colors=_series_color(ch.spec, field, i)),
                             static=True)
        self._log_session_text(summary=None)
        self.rec.send_blueprint(flight_blueprint(streams))
        if self.background:
            self._thread = threading.Thread(target=self._run, name="rerun-view", daemon=True)
            self._thread.start()

    def rows(self, stream: str, rows: Sequence[tuple]) -> None:
        """Queue rows of ``stream`` (never blocks, never raises)."""
        n = len(rows)
        if self._n_queued + n - self._n_taken > self.max_pending_rows:
            self.dropped_rows += n
            self._warn_once("full", "view is behind: dropping rows (the session file keeps them)")
            return
        self._pending.append((stream, list(rows)))
        self._n_queued += n

    def end(self, *, summary: Mapping[str, Any]) -> None:
        """Send what is queued, log the summary, flush; close the sink in mode 'save'."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        self.flush()
        self._flush_event()
        self._log_session_text(summary=summary)
        if self.dropped_rows:
            log.warning("view dropped %d rows", self.dropped_rows)
        if self.rrd_path is None:
            self.rec.flush()
            return
        try:
            close_file(self.rec, self.rrd_path)
        except RecordingFileError as exc:
            raise ViewError(str(exc)) from None

    # ------------------------------------------------------------------ sending
    def flush(self) -> None:
        """Send every queued row now: the worker does this every ``flush_interval``; call it
        yourself only with ``background=False`` (one thread takes rows off the queue)."""
        batches: dict[str, list[tuple]] = {}
        while self._pending:
            stream, rows = self._pending.popleft()
            batches.setdefault(stream, []).extend(rows)
        self._n_taken += sum(len(b) for b in batches.values())
        for stream, rows in batches.items():
            ch = self._streams.get(stream)
            if ch is None:
                self._warn_once(stream, f"rows for undeclared stream {stream!r} ignored")
                continue
            try:
                self.send_block(stream, np.array(rows, dtype=ch.spec.dtype))
            except Exception:  # a bad row must not stop the view, nor the flight
                log.exception("view could not show %d rows of %s", len(rows), stream)

    def send_block(self, stream: str, data: np.ndarray) -> None:
        """Send a structured array ``(n_rows,)`` of ``stream`` (dtype of its spec) at once."""
        ch = self._streams[stream]
        if len(data) == 0:
            return
        t = data["host_time"].astype(np.float64)
        lacking = [f for f in _KIND_FIELDS.get(ch.spec.kind, ()) if f not in (data.dtype.names
                                                                             or ())]
        if lacking:  # a file from elsewhere: a stream of that kind without its fields
            log.warning("stream %s (kind %s) has no field %s: not shown", stream, ch.spec.kind,
                        lacking[0])
            return
        with self._lock:
            if ch.spec.kind == "events":
                shown = self._event_rows_timed(t, data)
                self._send_events(t, data)
            elif ch.spec.kind == "phases":
                shown = _timed(t)
                self._send_phases(t, data)
            elif ch.spec.kind == "live_id":
                from groundstation.liveid_view import send_rows

                shown = _timed(t)
                send_rows(self.rec, data)
            else:
                times = [("host_time", t)]
                if ch.firmware_time:
                    times.append(("fw_time", self._unwrap(stream, data["fw_time_ms"])))
                shown = np.logical_and.reduce([_timed(a) for _, a in times])
                self._send_numeric(ch, times, data)
            n_shown = int(np.count_nonzero(shown))
            self.sent_rows[stream] = self.sent_rows.get(stream, 0) + n_shown
            if n_shown < len(data):
                self.untimed_rows[stream] = (self.untimed_rows.get(stream, 0)
                                             + len(data) - n_shown)

    def _event_rows_timed(self, t: np.ndarray, data: np.ndarray) -> np.ndarray:
        """Which rows of an events block are shown: those of an event (a row and the rows
        continuing it) whose first row has a usable time, as :meth:`_send_events` joins them
        (a block's leading continuation rows belong to the event the last block left open)."""
        n = len(data)
        starts = np.where(data["cont"].astype(bool), -1, np.arange(n))
        if self._last_event is None and n:
            starts[0] = 0  # nothing to continue: the first row starts an event
        owner = np.maximum.accumulate(starts)
        last_t = self._last_event[0] if self._last_event is not None else np.nan
        return _timed(np.where(owner >= 0, t[np.maximum(owner, 0)], last_t))

    def _send_numeric(self, ch: _Channels, times: list[tuple[str, np.ndarray]],
                      data: np.ndarray) -> None:
        timed = np.ones(len(data), dtype=bool)
        for _, a in times:
            timed &= _timed(a)
        _warn_untimed(timed, ch.spec.name)
        # the whole block's times only when all usable (Rerun warns converting an inf)
        full = [rr.TimeColumn(name, duration=v) for name, v in times] if timed.all() else []
        for field, entity in ch.channels:
            v = data[field].astype(np.float64)
            ok = np.isfinite(v) & timed
            if ok.all():
                indexes = full
            elif ok.any():
                indexes = [rr.TimeColumn(name, duration=a[ok]) for name, a in times]
                v = v[ok]
            else:
                continue
            self.rec.send_columns(entity, indexes=indexes,
                                  columns=rr.Scalars.columns(scalars=v))

    def _unwrap(self, stream: str, raw: np.ndarray) -> np.ndarray:
        """Firmware seconds with 24-bit wraps undone, continuing across blocks."""
        ms = raw.astype(np.int64)
        last, wraps = self._fw_state.get(stream, (int(ms[0]), 0))
        steps = np.diff(np.concatenate([[last], ms])) < -(_WRAP // 2)
        count = wraps + np.cumsum(steps)
        self._fw_state[stream] = (int(ms[-1]), int(count[-1]))
        return (ms + count * _WRAP) / 1000.0

    def _send_events(self, t: np.ndarray, data: np.ndarray) -> None:
        """Events as a text log; a text continued on following rows (``cont``) is joined."""
        out: list[tuple[float, str, str, bytes]] = []
        pending = self._last_event
        for i in range(len(data)):
            piece = bytes(data["text"][i])
            if data["cont"][i] and pending is not None:
                pending = (*pending[:3], pending[3] + piece)
                continue
            if pending is not None:
                out.append(pending)
            src = bytes(data["source"][i]).decode("utf-8", errors="replace")
            pending = (float(t[i]), _LEVELS.get(int(data["level"][i]), "INFO"), src, piece)
        self._last_event = pending  # may still be continued by the next block
        self._log_events(out)

    def _flush_event(self) -> None:
        with self._lock:
            if self._last_event is not None:
                self._log_events([self._last_event])
                self._last_event = None

    def _log_events(self, events: list[tuple[float, str, str, bytes]]) -> None:
        timed = _timed(np.array([e[0] for e in events], dtype=float))
        if not _warn_untimed(timed, "events"):  # one bad time lost every event
            events = [e for e, ok in zip(events, timed, strict=True) if ok]
        if not events:
            return
        texts = [f"[{e[2]}] {e[3].decode('utf-8', errors='replace')}" for e in events]
        self.rec.send_columns(
            EVENTS, indexes=[rr.TimeColumn("host_time", duration=[e[0] for e in events])],
            columns=rr.TextLog.columns(text=texts, level=[e[1] for e in events]))

    def _send_phases(self, t: np.ndarray, data: np.ndarray) -> None:
        timed = _timed(t)
        if not _warn_untimed(timed, "phases"):  # one bad time lost every phase
            t, data = t[timed], data[timed]
        names = [bytes(v).decode("utf-8", errors="replace") for v in data["name"]]
        kinds = [bytes(v).decode("utf-8", errors="replace") for v in data["kind"]]
        ids = data["phase_id"].astype(int)
        self.rec.send_columns(
            PHASE, indexes=[rr.TimeColumn("host_time", duration=t)],
            columns=[*rr.StateChange.columns(state=[f"{n} ({k})" for n, k in
                                                    zip(names, kinds, strict=True)]),
                     *rr.TextLog.columns(text=[f"phase {i}: {n} ({k})" for i, n, k in
                                               zip(ids, names, kinds, strict=True)],
                                         level=["INFO"] * len(ids))])

    def _log_session_text(self, *, summary: Mapping[str, Any] | None) -> None:
        meta = self._metadata
        lines = [f"**{k}**: {meta[k]}" for k in _META_KEYS if _shown(meta.get(k))]
        lines += [f"**problem**: {p}" for p in meta.get("problems", [])]
        if summary is not None:
            lines.append("\n**summary**\n\n```\n" +
                         json.dumps(dict(summary), indent=1, sort_keys=True, default=str) +
                         "\n```")
        with self._lock:
            self.rec.log(SESSION, rr.TextDocument("\n\n".join(lines) or "(no metadata)",
                                                    media_type=rr.MediaType.MARKDOWN),
                         static=True)

    # ------------------------------------------------------------------ worker
    def _run(self) -> None:
        while not self._stop.wait(self.flush_interval):
            try:
                self.flush()
            except Exception:
                log.exception("view worker")

    def _warn_once(self, key: str, message: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            log.warning(message)


def open_view(*, mode: Literal["rerun", "serve", "save"], name: str,
              rrd_path: Path | None = None, web_port: int = WEB_PORT) -> RerunView:
    """A flight view (a :class:`FlightListener`).

    ``mode``: ``rerun`` (native viewer, or the web viewer without a display), ``serve`` (web
    viewer on 127.0.0.1:``web_port``, 0 for any free port; its URL is in ``view.url`` for the
    caller to print) or ``save`` (``rrd_path``, complete once ``end`` returns, or a
    :class:`ViewError` when it could not be written). A busy port is a
    one-line :class:`ViewError`, raised before anything flies.
    """
    try:
        rec, url = open_recording(name=name, mode=mode, rrd_path=rrd_path,
                                  application_id="crazyflie-groundstation", web_port=web_port)
    except ViewModeError as exc:
        raise ViewError(str(exc)) from None
    return RerunView(rec=rec, url=url, rrd_path=rrd_path if mode == "save" else None)


def plot_plan(*, schedule: Schedule, view: RerunView) -> None:
    """Show a compiled plan's setpoints and phases in ``view`` exactly as a flight's
    setpoints would be shown (time axis ``host_time`` = plan time, s); ends the view."""
    sp, ph = setpoints_spec(), phases_spec()
    n = len(schedule.t)
    setpoints = np.zeros(n, dtype=sp.dtype)
    setpoints["host_time"] = schedule.t
    for axis in ("roll", "pitch", "yaw_rate", "thrust", "phase_id"):
        setpoints[axis] = getattr(schedule, axis)
    setpoints["tick"] = np.arange(n)
    phases = np.array([(p.start, p.id, p.name.encode()[:32], p.kind.encode()[:16])
                       for p in schedule.phases], dtype=ph.dtype)
    view.begin(streams=[sp, ph], metadata={"plan_name": schedule.name})
    view.send_block("setpoints", setpoints)
    view.send_block("phases", phases)
    view.end(summary={"setpoints": n, "rate_hz": schedule.rate_hz,
                      "duration_s": float(n / schedule.rate_hz)})


def _shown(value: Any) -> bool:
    """A metadata value worth a line: not missing, empty or NaN (an array from a file made
    elsewhere is shown as it is; comparing it raised "truth value ... is ambiguous")."""
    if value is None or (isinstance(value, str) and not value):
        return False
    if isinstance(value, float):
        return value == value  # not NaN
    return True
