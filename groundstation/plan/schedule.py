"""The compiled flight plan the runner streams: setpoints on a fixed grid, phases, abort policy.

A :class:`Schedule` (built by :meth:`groundstation.plan.Plan.compile`, re-exported there) holds
``n`` setpoints at times :math:`t_k = k / f_s`, :math:`k = 0 \\dots n - 1`, each held for one
period :math:`1 / f_s`, so ``duration`` = :math:`n / f_s`. Setpoint :math:`k` is sent as
``Commander.send_setpoint(roll[k], pitch[k], yaw_rate[k], thrust[k])`` (:meth:`Schedule.setpoint`).
All arrays have shape ``(n,)`` and are read-only; units are in :data:`UNITS`.

Construction re-checks every setpoint against the :class:`VehicleLimits` (the plan loader has
already refused out-of-limit keys with their line; this is the last line of defence and covers
hand-made schedules), so a Schedule that exists is within its vehicle's limits; a nan setpoint,
a nan or infinite limit or rate is refused too.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from groundstation.errors import PlanError
from groundstation.plan.altitude import AltitudeHoldConfig

__all__ = ["BATTERY_FLIGHT_S", "MAX_RATE_RANGE_DEG_S", "SETPOINT_CHANNELS", "UNITS", "Phase",
           "Safety", "Schedule", "VehicleLimits"]

log = logging.getLogger(__name__)

SETPOINT_CHANNELS = ("roll", "pitch", "yaw_rate", "thrust")
"""Setpoint channels in the order of ``Commander.send_setpoint(roll, pitch, yawrate, thrust)``."""
UNITS = {"t": "s", "roll": "deg", "pitch": "deg", "yaw_rate": "deg/s", "thrust": "PWM"}


def _require_finite(obj: Any, table: str) -> None:
    """Refuse nan/inf in a limits dataclass: a nan limit compares false and would disable it."""
    for key, value in vars(obj).items():
        if isinstance(value, int | float) and not np.isfinite(value):
            raise PlanError(f"{table}.{key} = {value!r} is not a finite number")


BATTERY_FLIGHT_S = 420.0
"""Seconds a Crazyflie flies on one battery, ``vehicle.flight_time_s``'s default: about 7
minutes, Bitcraze's figure for the Crazyflie 2.x on its stock 250 mAh battery and the thesis'
for its Crazyflie (170 mAh; section 4.1, "Quadrotor Platform"), hovering: the excitation's
tilt and a battery not quite full shorten it."""


@dataclass(frozen=True)
class VehicleLimits:
    """The plan's ``[vehicle]`` table: hard limits every setpoint must respect."""

    max_roll_deg: float
    max_pitch_deg: float
    max_yaw_rate_deg_s: float
    thrust_min: int  # PWM, 0-65535
    thrust_max: int  # PWM
    min_vbat: float  # V: battery voltage needed to take off
    flight_time_s: float = BATTERY_FLIGHT_S  # s one battery flies; a longer plan is warned about

    def __post_init__(self) -> None:
        _require_finite(self, "vehicle")


MAX_RATE_RANGE_DEG_S = (10.0, 5000.0)
"""The gyro-rate abort's accepted range, deg/s: ``[safety] max_rate_deg_s`` and ``fly
--max-rate`` alike (below, a hover's noise aborts; above, no tumble ever would)."""


@dataclass(frozen=True)
class Safety:
    """The plan's ``[safety]`` table. ``on_abort``: ``"stop"`` (motors off at once) or
    ``"descend"`` (level out at ``descent_thrust`` PWM for ``descent_duration`` s, then stop)."""

    on_abort: str = "stop"
    descent_duration: float = 0.0  # s
    descent_thrust: int = 0  # PWM
    max_rate_deg_s: float | None = None  # abort beyond this |gyro| (None: the runner's default)

    def __post_init__(self) -> None:
        _require_finite(self, "safety")


@dataclass(frozen=True)
class Phase:
    """A named phase covering ticks ``[start_tick, end_tick)``; ``id`` is its index."""

    id: int
    name: str
    kind: str  # takeoff | hover | excitation | landing | abort
    start_tick: int
    end_tick: int
    rate_hz: float

    @property
    def start(self) -> float:
        """Start time in s from the beginning of the schedule."""
        return self.start_tick / self.rate_hz

    @property
    def end(self) -> float:
        """End time in s (the end of the last setpoint period of the phase)."""
        return self.end_tick / self.rate_hz

    @property
    def duration(self) -> float:
        return (self.end_tick - self.start_tick) / self.rate_hz

    @property
    def n_ticks(self) -> int:
        return self.end_tick - self.start_tick

    def to_dict(self) -> dict[str, Any]:
        return {
            "id": self.id,
            "name": self.name,
            "kind": self.kind,
            "start_s": self.start,
            "end_s": self.end,
            "start_tick": self.start_tick,
            "end_tick": self.end_tick,
        }


_LIMITS = {"roll": "max_roll_deg", "pitch": "max_pitch_deg", "yaw_rate": "max_yaw_rate_deg_s"}


@dataclass(frozen=True, eq=False)
class Schedule:
    """Setpoints on a ``rate_hz`` grid: ``t``, ``roll``, ``pitch``, ``yaw_rate`` (float, shape
    ``(n,)``), ``thrust`` (int PWM), ``phase_id`` (index into ``phases``)."""

    name: str
    rate_hz: float
    roll: np.ndarray
    pitch: np.ndarray
    yaw_rate: np.ndarray
    thrust: np.ndarray
    phase_id: np.ndarray
    phases: tuple[Phase, ...]
    vehicle: VehicleLimits
    safety: Safety = Safety()
    altitude_hold: AltitudeHoldConfig | None = None
    t: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        n = len(self.thrust)
        for name, dtype in (
            ("roll", float),
            ("pitch", float),
            ("yaw_rate", float),
            ("thrust", np.int64),
            ("phase_id", np.int64),
        ):
            arr = np.array(getattr(self, name), dtype=dtype)
            if arr.shape != (n,):
                raise PlanError(f"schedule {name} has shape {arr.shape}, expected ({n},)")
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise PlanError(f"schedule rate_hz = {self.rate_hz!r} must be a finite number > 0")
        t = np.arange(n) / self.rate_hz
        t.flags.writeable = False
        object.__setattr__(self, "t", t)
        self._check_phases()
        self._check_limits()

    def _check_phases(self) -> None:
        k = 0
        for i, p in enumerate(self.phases):
            if p.id != i or p.start_tick != k or p.end_tick <= k:
                raise PlanError(f"schedule phase {p.name!r} does not follow on at tick {k}")
            if np.any(self.phase_id[p.start_tick : p.end_tick] != i):
                raise PlanError(f"schedule phase_id disagrees with phase {p.name!r}")
            k = p.end_tick
        if k != len(self):
            raise PlanError(f"schedule phases cover {k} ticks but there are {len(self)}")

    def _check_limits(self) -> None:
        v = self.vehicle
        # `~(x <= limit)` rather than `x > limit`: a nan setpoint is refused, not let through
        checks = [
            (axis, ~(np.abs(getattr(self, axis)) <= getattr(v, key)), key, getattr(v, key))
            for axis, key in _LIMITS.items()
        ]
        checks += [
            ("thrust", ~(self.thrust >= v.thrust_min), "thrust_min", v.thrust_min),
            ("thrust", ~(self.thrust <= v.thrust_max), "thrust_max", v.thrust_max),
        ]
        for axis, bad, key, limit in checks:
            if np.any(bad):
                k = int(np.argmax(bad))
                raise PlanError(
                    f"schedule {self.name!r}: {axis} = {getattr(self, axis)[k]:g} "
                    f"{UNITS[axis]} at t = {k / self.rate_hz:g} s violates vehicle.{key} = "
                    f"{limit:g}; change the plan or the limit"
                )

    def __len__(self) -> int:
        return len(self.thrust)

    @property
    def duration(self) -> float:
        """Seconds: ``len(self) / rate_hz``."""
        return len(self) / self.rate_hz

    @property
    def period(self) -> float:
        """Seconds between setpoints."""
        return 1.0 / self.rate_hz

    def setpoint(self, k: int) -> tuple[float, float, float, int]:
        """Setpoint ``k``: ``(roll deg, pitch deg, yaw_rate deg/s, thrust PWM)``, cflib's order."""
        return (
            float(self.roll[k]),
            float(self.pitch[k]),
            float(self.yaw_rate[k]),
            int(self.thrust[k]),
        )

    def as_array(self) -> np.ndarray:
        """All setpoints, shape ``(n, 4)``, columns :data:`SETPOINT_CHANNELS`."""
        return np.column_stack([self.roll, self.pitch, self.yaw_rate, self.thrust.astype(float)])

    def phase_at(self, k: int) -> Phase:
        """The phase setpoint ``k`` belongs to."""
        return self.phases[int(self.phase_id[k])]

    def abort_schedule(self, tick: int) -> Schedule:
        """Setpoints to send after an abort at setpoint ``tick``, then ``send_stop_setpoint()``.

        ``on_abort = "stop"``, or an abort at or after the end: empty (stop at once).
        ``"descend"``: ``descent_duration`` s of level attitude (roll = pitch = yaw rate = 0)
        at thrust :math:`\\min(\\text{thrust}_{\\text{tick}}, \\text{descent\\_thrust})`, so
        an abort during a low take-off ramp never climbs; one phase of kind ``"abort"``.
        """
        n_abort = round(self.safety.descent_duration * self.rate_hz)
        if self.safety.on_abort != "descend" or tick >= len(self) or n_abort == 0:
            n_abort = 0
        thrust = (
            min(int(self.thrust[max(int(tick), 0)]), self.safety.descent_thrust) if n_abort else 0
        )
        zeros = np.zeros(n_abort)
        phases = (
            (
                Phase(
                    id=0,
                    name="abort",
                    kind="abort",
                    start_tick=0,
                    end_tick=n_abort,
                    rate_hz=self.rate_hz,
                ),
            )
            if n_abort
            else ()
        )
        log.info("abort at tick %d: %d descent setpoints at thrust %d", tick, n_abort, thrust)
        return Schedule(
            name=f"{self.name}:abort",
            rate_hz=self.rate_hz,
            roll=zeros,
            pitch=zeros,
            yaw_rate=zeros,
            thrust=np.full(n_abort, thrust),
            phase_id=np.zeros(n_abort, dtype=np.int64),
            phases=phases,
            vehicle=self.vehicle,
            safety=Safety(),
        )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: metadata, units, phases and the setpoint arrays as lists."""
        return {
            "name": self.name,
            "rate_hz": self.rate_hz,
            "duration_s": self.duration,
            "n_setpoints": len(self),
            "units": dict(UNITS),
            "vehicle": vars(self.vehicle),
            "safety": vars(self.safety),
            "phases": [p.to_dict() for p in self.phases],
            "setpoints": {
                "t": self.t.tolist(),
                "roll": self.roll.tolist(),
                "pitch": self.pitch.tolist(),
                "yaw_rate": self.yaw_rate.tolist(),
                "thrust": self.thrust.tolist(),
                "phase_id": self.phase_id.tolist(),
            },
        }
