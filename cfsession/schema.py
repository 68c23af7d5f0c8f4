"""The session file's schema: stream kinds, their fields and units.

A session file holds one group per stream; each group holds ONE resizable dataset ``data`` whose
compound dtype makes a row atomic. Every stream's first field is ``host_time`` (seconds on the
flight clock since the session started); log-block streams carry ``fw_time_ms`` (the Crazyflie's
millisecond tick, as sent: 24 bits, wrapping) second. See ``docs/session-format.md``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "CFLIB_TYPES",
    "SCHEMA_NAME",
    "SCHEMA_VERSION",
    "TEXT_BYTES",
    "Field",
    "StreamSpec",
    "events_spec",
    "link_spec",
    "live_id_spec",
    "log_block_spec",
    "phases_spec",
    "setpoints_spec",
    "unit_of",
]

SCHEMA_NAME = "crazyflie-flight-session"
SCHEMA_VERSION = 1
TEXT_BYTES = 200
"""Bytes of UTF-8 text per event row; longer texts continue on following rows (``cont`` = 1)."""

CFLIB_TYPES: dict[str, str] = {
    "uint8_t": "u1",
    "uint16_t": "<u2",
    "uint32_t": "<u4",
    "int8_t": "i1",
    "int16_t": "<i2",
    "int32_t": "<i4",
    "float": "<f4",
    "double": "<f8",
    "FP16": "<f4",
}
"""cflib log/param type names -> numpy dtype strings."""

_UNITS_BY_GROUP = {
    "motor": "PWM (0-65535)",
    "pwm": "PWM (0-65535)",
    "acc": "g",
    "gyro": "deg/s",
    "mag": "gauss",
    "baro": "hPa",
}
_UNITS_BY_NAME = {
    "stabilizer.roll": "deg",
    "stabilizer.pitch": "deg",
    "stabilizer.yaw": "deg",
    "stabilizer.thrust": "PWM (0-65535)",
    "pm.vbat": "V",
    "pm.vbatMV": "mV",
    "baro.asl": "m",
    "stateEstimate.x": "m",
    "stateEstimate.y": "m",
    "stateEstimate.z": "m",
    "stateEstimate.vx": "m/s",
    "stateEstimate.vy": "m/s",
    "stateEstimate.vz": "m/s",
    "stateEstimate.ax": "g",
    "stateEstimate.ay": "g",
    "stateEstimate.az": "g",
    "stateEstimate.roll": "deg",
    "stateEstimate.pitch": "deg",
    "stateEstimate.yaw": "deg",
    # controller_pid.c: outputs (mixer inputs), gyro in rad/s, attitude/rate setpoints
    "controller.cmd_thrust": "PWM (0-65535)",
    "controller.cmd_roll": "cmd (int16 range)",
    "controller.cmd_pitch": "cmd (int16 range)",
    "controller.cmd_yaw": "cmd (int16 range)",
    "controller.r_roll": "rad/s",
    "controller.r_pitch": "rad/s",
    "controller.r_yaw": "rad/s",
    "controller.accelz": "g",
    "controller.actuatorThrust": "PWM (0-65535)",
    "controller.roll": "deg",
    "controller.pitch": "deg",
    "controller.yaw": "deg",
    "controller.rollRate": "deg/s",
    "controller.pitchRate": "deg/s",
    "controller.yawRate": "deg/s",
    "controller.ctr_yaw": "cmd (int16 range)",
}


def unit_of(variable: str) -> str:
    """Best-known unit of a Crazyflie log variable ``group.name`` ('' when unknown)."""
    if variable in _UNITS_BY_NAME:
        return _UNITS_BY_NAME[variable]
    return _UNITS_BY_GROUP.get(variable.split(".", 1)[0], "")


@dataclass(frozen=True)
class Field:
    """One column of a stream: its name in the dtype, numpy dtype, unit and source."""

    name: str
    dtype: str
    unit: str = ""
    source: str = ""


@dataclass(frozen=True)
class StreamSpec:
    """What a stream holds. ``kind`` is one of log, setpoints, events, phases, link."""

    name: str
    kind: str
    fields: tuple[Field, ...]
    period_s: float | None = None
    description: str = ""
    attrs: dict[str, str | float | int] = field(default_factory=dict)

    @property
    def dtype(self) -> np.dtype:
        return np.dtype([(f.name, f.dtype) for f in self.fields])

    def fill_row(self) -> np.ndarray:
        """The dataset's fill value: NaN host time marks a row resized but never written."""
        row = np.zeros((), dtype=self.dtype)
        row["host_time"] = np.nan
        return row


_HOST = Field("host_time", "<f8", "s", "host: flight clock, seconds since session start")
_FW = Field("fw_time_ms", "<u4", "ms", "Crazyflie firmware tick (24-bit, wraps)")


def log_block_spec(
    *, name: str, variables: Sequence[tuple[str, str]], period_s: float
) -> StreamSpec:
    """A log block as logged: ``variables`` are ``(group.name, cflib type)`` in block order.

    Field names are the variable names without their group (``motor.m1`` -> ``m1``), or the full
    name with ``.`` replaced by ``_`` when two variables of the block share a short name.
    """
    shorts = [v.split(".", 1)[-1] for v, _ in variables]
    fields = [_HOST, _FW]
    for (var, ctype), short in zip(variables, shorts, strict=True):
        if ctype not in CFLIB_TYPES:
            raise ValueError(f"log variable {var}: unknown type {ctype!r}")
        fname = short if shorts.count(short) == 1 else var.replace(".", "_")
        fields.append(Field(fname, CFLIB_TYPES[ctype], unit_of(var), var))
    return StreamSpec(
        name=name,
        kind="log",
        fields=tuple(fields),
        period_s=period_s,
        description=f"log block '{name}' every {period_s * 1000:.0f} ms",
        attrs={"cflib_types": ",".join(t for _, t in variables)},
    )


def setpoints_spec() -> StreamSpec:
    """Setpoints as sent with ``Commander.send_setpoint`` (before cflib negates pitch)."""
    return StreamSpec(
        name="setpoints",
        kind="setpoints",
        fields=(
            Field("host_time", "<f8", "s", "host: send time on the flight clock"),
            Field("roll", "<f4", "deg", "commander roll setpoint"),
            Field("pitch", "<f4", "deg", "commander pitch setpoint (as passed to cflib)"),
            Field("yaw_rate", "<f4", "deg/s", "commander yaw-rate setpoint"),
            Field("thrust", "<u2", "PWM (0-65535)", "commander thrust"),
            Field("phase_id", "<i2", "", "index into the phases stream's phase table"),
            Field("tick", "<i4", "", "setpoint index in the plan's schedule (-1: not scheduled)"),
        ),
        description="every setpoint sent, with its send time",
    )


def events_spec() -> StreamSpec:
    """Phase changes, warnings, link events, console lines; long texts span rows."""
    return StreamSpec(
        name="events",
        kind="events",
        fields=(
            _HOST,
            Field("level", "u1", "", "logging level / 10: 1 debug, 2 info, 3 warning, 4 error"),
            Field("source", "S16", "", "who said it: runner, link, console, safety, ..."),
            Field("text", f"S{TEXT_BYTES}", "", "UTF-8 text"),
            Field("cont", "u1", "", "1 if this row continues the previous row's text"),
        ),
        description="events and console text",
    )


def phases_spec() -> StreamSpec:
    """One row each time the flight enters a phase."""
    return StreamSpec(
        name="phases",
        kind="phases",
        fields=(
            _HOST,
            Field("phase_id", "<i2", "", "phase index in the plan (-1: outside the plan)"),
            Field("name", "S32", "", "phase name"),
            Field("kind", "S16", "", "takeoff, hover, excitation, landing, abort, ..."),
        ),
        description="phase markers: a phase lasts until the next row or the end",
    )


def link_spec() -> StreamSpec:
    """Link quality and latency samples (NaN where a sample carries only one of them)."""
    return StreamSpec(
        name="link",
        kind="link",
        fields=(
            _HOST,
            Field("quality", "<f4", "%", "cflib link quality (0-100)"),
            Field("latency_ms", "<f4", "ms", "round-trip latency"),
        ),
        description="link quality and latency",
    )


LIVE_ID_POLE_UNIT = "1 (z-plane)"


def live_id_spec(*, order: int, attrs: dict[str, str | float | int] | None = None) -> StreamSpec:
    """One row per live identification update (``groundstation fly --live-id``,
    ``docs/live-id.md``); the ``order`` poles as two float columns each, sorted by descending
    magnitude (a conjugate pair: negative imaginary part first). ``attrs`` describe the
    settings (channels, horizons, grid period)."""
    fields = [
        Field("host_time", "<f8", "s", "host: flight time the update started (newest row)"),
        Field("fw_end_s", "<f8", "s", "Crazyflie time of the newest grid sample (wraps undone)"),
        Field("span_s", "<f4", "s", "data span of the update: n_samples x grid period"),
        Field("n_samples", "<u4", "", "grid samples identified from"),
        Field("order", "<u2", "", "model order"),
        Field("past", "<u2", "", "past horizon, grid samples"),
        Field("future", "<u2", "", "future horizon, grid samples"),
        Field("fit_pct", "<f4", "%", "one-step-ahead fit on the most recent data, mean over "
              "outputs"),
        Field("innovation_nvar", "<f4", "1", "one-step prediction error variance over output "
              "variance on the most recent data, mean over outputs"),
        Field("pole_move", "<f4", LIVE_ID_POLE_UNIT, "largest distance of a pole to the nearest "
              "pole of the previous update (Hausdorff distance; NaN at the first)"),
        Field("max_pole", "<f4", LIVE_ID_POLE_UNIT, "largest pole magnitude"),
        Field("update_s", "<f4", "s", "wall time the update took"),
        Field("skipped", "<u4", "", "updates skipped so far (the worker was behind)"),
        Field("final", "u1", "", "1: the last update of the excitation (the saved model)"),
    ]
    for i in range(1, order + 1):
        fields += [Field(f"pole_re_{i}", "<f8", LIVE_ID_POLE_UNIT, f"pole {i}, real part"),
                   Field(f"pole_im_{i}", "<f8", LIVE_ID_POLE_UNIT, f"pole {i}, imaginary part")]
    return StreamSpec(
        name="live_id",
        kind="live_id",
        fields=tuple(fields),
        description="live identification: one row per model update during the excitation",
        attrs=dict(attrs or {}),
    )
