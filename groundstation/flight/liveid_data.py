"""The data of live identification (:mod:`groundstation.flight.liveid`): which log variables
it uses (``[live_id]`` inputs and outputs, checked against the log streams of a flight before
connecting, :func:`planned_streams`, and at its start, the streams as recorded),
:class:`Feed`, one stream's rows on their way to the grid (firmware time unwrapped), and
:class:`ExcitationGrid`, the recorded excitation held onto the grid (the **Data** paragraph of
:mod:`groundstation.flight.liveid`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np

from cfsession.channels import Channel
from cfsession.channels import resolve_channels as _resolve
from cfsession.errors import ChannelError
from cfsession.schema import StreamSpec
from groundstation.errors import PlanError
from groundstation.flight.blocks import flight_blocks
from groundstation.plan import LiveIdConfig, Plan
from groundstation.plan.toml import TomlSource

__all__ = ["Channel", "ExcitationGrid", "Feed", "check_live_id", "live_id_error",
           "planned_streams", "resolve_channels"]

_WRAP = 1 << 24  # log packets carry a 24-bit millisecond tick


def planned_streams(plan: Plan) -> list[StreamSpec]:
    """The log streams a flight of ``plan`` records (:func:`flight_blocks`; types as 'float':
    only names matter)."""
    hold = plan.altitude_hold
    return [b.spec() for b in flight_blocks(
        toc_type=lambda _: "float", altitude_variable=hold.variable if hold else None,
        setpoint_period_s=1.0 / plan.setpoint_rate_hz)]


def live_id_error(source: TomlSource | None, key: str, message: str) -> PlanError:
    """``FILE:LINE: live_id.KEY: message`` with the plan's text, else ``live_id: message``
    (``--live-id`` on a plan without the table: the defaults, no line to name)."""
    if source is None:
        return PlanError(f"live_id: {message}")
    return source.error(("live_id", key), message)


def resolve_channels(names: Sequence[str], *, streams: Sequence[StreamSpec],
                     role: Literal["input", "output"], source: TomlSource | None = None
                     ) -> list[Channel]:
    """The log variables ``names`` select, in order, by the rule of offline identification
    (:func:`cfsession.channels.resolve_channels`: a log stream, ``stream.field``, a logged
    variable such as ``motor.m1`` or a variable group such as ``gyro``). One-line
    :class:`PlanError` otherwise, naming the key and its line in ``source`` (the plan's
    text) when given."""
    try:
        return _resolve(names, streams=streams, role=role)
    except ChannelError as exc:
        key = f"{role}s"
        if exc.problem == "unknown":
            raise live_id_error(source, key, f"{role} {exc.name!r}: no such log stream or "
                                f"variable; the flight logs {', '.join(exc.logged)} (name a "
                                "stream, STREAM.FIELD, a variable or a variable group)") from None
        raise live_id_error(source, key, str(exc)) from None


def check_live_id(config: LiveIdConfig, *, streams: Sequence[StreamSpec],
                  source: TomlSource | None = None
                  ) -> tuple[list[Channel], list[Channel], float]:
    """Inputs, outputs and the grid period for ``config`` on these log streams; one-line
    :class:`PlanError` for a name logged nowhere, a channel selected twice, channels logged
    at different rates or an order beyond the horizons' rank, naming the ``[live_id]`` key
    and its line when ``source`` (a :class:`TomlSource` of the plan's text) is given."""
    ins = resolve_channels(config.inputs, streams=streams, role="input", source=source)
    outs = resolve_channels(config.outputs, streams=streams, role="output", source=source)
    labels = [c.label for c in ins + outs]
    twice = sorted({x for x in labels if labels.count(x) > 1})
    if twice:
        in_labels = [c.label for c in ins]
        within = any(in_labels.count(x) > 1 for x in twice)
        raise live_id_error(source, "inputs" if within else "outputs",
                            f"{twice} selected twice (inputs and outputs); name each once")
    periods = {s.name: s.period_s for s in streams if any(c.stream == s.name for c in ins + outs)}
    if len({round(p or 0.0, 9) for p in periods.values()}) != 1 or not all(periods.values()):
        rates = ", ".join(f"{n} every {1000 * (p or 0):g} ms" for n, p in sorted(periods.items()))
        mixed_inputs = len({round(s.period_s or 0.0, 9) for s in streams
                            if any(c.stream == s.name for c in ins)}) > 1
        raise live_id_error(source, "inputs" if mixed_inputs else "outputs",
                            f"the channels are logged at different rates ({rates}); live "
                            "identification needs one rate (no anti-alias filter in flight)")
    m, ell, c = len(ins), len(outs), config
    limit = min((c.future - 1) * ell, c.past * (m + ell))
    if c.order > limit:
        raise live_id_error(source, "order", f"order {c.order} exceeds the rank available "
                            f"(min((future - 1) x {ell} outputs, past x {m + ell} channels) = "
                            f"{limit}); lower the order or raise the horizons")
    return ins, outs, float(next(iter(periods.values())))


class Feed:
    """One log stream's rows not yet used by the grid: host s, firmware s, selected values."""

    def __init__(self, *, columns: list[int]) -> None:
        self.columns = columns
        self.host = np.empty(0)
        self.fw = np.empty(0)
        self.values = np.empty((0, len(columns)))
        self.last_raw: int | None = None
        self.wraps = 0
        self.max_host = -np.inf  # host time of the newest row received (kept or not)
        self.offset = 0.0  # host - firmware time of the newest rows (latency included)

    def add(self, rows: Sequence[tuple]) -> None:
        a = np.asarray(rows, dtype=float)
        raw = a[:, 1].astype(np.int64)
        prev = raw[0] if self.last_raw is None else self.last_raw
        wraps = self.wraps + np.cumsum(np.diff(np.concatenate([[prev], raw])) < -(_WRAP // 2))
        self.last_raw, self.wraps = int(raw[-1]), int(wraps[-1])
        self.max_host = max(self.max_host, float(a[-1, 0]))
        fw = (raw + wraps * _WRAP) / 1000.0
        self.offset = float(np.median(a[:, 0] - fw))
        self.host = np.concatenate([self.host, a[:, 0]])
        self.fw = np.concatenate([self.fw, fw])
        self.values = np.concatenate([self.values, a[:, self.columns]])

    def keep(self, mask: np.ndarray) -> None:
        self.host, self.fw, self.values = self.host[mask], self.fw[mask], self.values[mask]


class ExcitationGrid:
    """The rows of the selected streams inside the excitation window, held onto the grid
    :math:`g_j = g_0 + j\\,\\Delta t` on firmware time (worker thread only).

    The window opens at the first excitation phase marker and closes at the marker of the
    first phase after the last excitation phase (``last_excitation``, a phase id; an abort
    marker, id below 0, closes it too). ``zoh`` is ``sysid.preprocess.zoh_resample``, handed in
    with the engine. :attr:`where` maps each channel, in order, to its stream and column."""

    def __init__(self, *, channels: Sequence[Channel], streams: Sequence[StreamSpec],
                 last_excitation: int | None, dt: float,
                 zoh: Callable[..., np.ndarray]) -> None:
        specs = {s.name: s for s in streams}
        self.feeds: dict[str, Feed] = {}
        self.where: list[tuple[str, int]] = []  # channel -> (stream, column in its feed)
        for ch in channels:
            names = [f.name for f in specs[ch.stream].fields]
            feed = self.feeds.setdefault(ch.stream, Feed(columns=[]))
            feed.columns.append(names.index(ch.field))
            self.where.append((ch.stream, len(feed.columns) - 1))
        for feed in self.feeds.values():
            feed.values = np.empty((0, len(feed.columns)))
        self.last_excitation, self.dt, self.zoh = last_excitation, dt, zoh
        self.window: list[float | None] = [None, None]  # host time the excitation starts, ends
        self.g0: float | None = None
        self.latest = -np.inf  # host time of the newest log row taken

    @property
    def offset(self) -> float:
        """Host minus firmware time of the newest rows (of the first selected stream)."""
        return next(iter(self.feeds.values())).offset

    def take(self, stream: str, rows: Sequence[tuple]) -> None:
        """Rows of a selected stream, or phase markers (``"phases"``: the window)."""
        if stream != "phases":
            self.feeds[stream].add(rows)
            self.latest = max(self.latest, float(rows[-1][0]))
            return
        for t, pid, _, kind in rows:
            start, stop = self.window
            if start is None and kind == b"excitation":
                self.window[0] = float(t)
            elif start is not None and stop is None and (
                    pid < 0 or self.last_excitation is None or pid > self.last_excitation):
                self.window[1] = float(t)

    def advance(self, *, n_done: int, stopping: bool) -> tuple[np.ndarray | None, bool]:
        """The held samples, (instants, channels), of the grid instants from ``n_done`` on
        that every stream now covers (None if none), and whether the window has closed and
        every row inside it has arrived."""
        start, stop = self.window
        feeds = list(self.feeds.values())
        if start is None:
            for f in feeds:  # before the excitation: keep the last seconds only
                f.keep(f.host >= self.latest - 5.0)
            return None, False
        for f in feeds:
            f.keep((f.host >= start) & (f.host < (np.inf if stop is None else stop)))
        complete = stop is not None and (stopping or all(f.max_host >= stop for f in feeds))
        if any(f.fw.size == 0 for f in feeds):
            return None, complete
        if self.g0 is None:
            self.g0 = max(float(f.fw[0]) for f in feeds)
        ready = min(float(f.fw[-1]) for f in feeds)
        j1 = int(np.floor((ready - self.g0) / self.dt + 1e-9)) + 1
        if j1 <= n_done:
            return None, complete
        grid = self.g0 + self.dt * np.arange(n_done, j1)
        held = {name: self.zoh(t=f.fw, values=f.values, grid=grid)
                for name, f in self.feeds.items()}
        for f in feeds:  # keep the sample held at the last grid instant, and later ones
            idx = max(int(np.searchsorted(f.fw, grid[-1] + 1e-9, side="right")) - 1, 0)
            f.keep(np.arange(f.fw.size) >= idx)
        return np.column_stack([held[s][:, i] for s, i in self.where]), complete
