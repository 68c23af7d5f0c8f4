"""Ground-station altitude hold: a slow PID on a logged altitude that trims the planned thrust.

The roll/pitch/yaw-rate/thrust commander has no altitude loop: thrust is open loop, and a hover
thrust error of 0.4 % integrates to metres within seconds while a ±25° PRBS tilts the thrust vector
away from vertical. A pilot would hold the height by hand; :class:`AltitudeHold` does it from the
vehicle's own altitude estimate (``stateEstimate.z`` by default), logged at twice the setpoint
rate (20 Hz at 10 Hz: :func:`groundstation.flight.blocks.altitude_block_period`), the newest
sample taken at each setpoint:

.. math::  e_k = z_\\text{ref} - z_k, \\qquad
           \\Delta T_k = \\operatorname{sat}_{\\pm\\Delta_\\max}\\Big(K_p e_k
           + \\sum_{j \\le k} K_i e_j h - K_d \\hat{\\dot z}_k\\Big),

with :math:`h` the setpoint period, :math:`\\hat{\\dot z}` a first-order-filtered finite difference
and the integral clamped to half the trim range (anti-windup). The runner sends
``thrust[k] + ΔT_k`` (clamped to the vehicle's thrust limits) and records the thrust as sent.
The loop only acts in the phase kinds listed in ``kinds`` (hover and excitation by default); it
starts from zero trim when the first such phase begins, so take-off and landing stay as planned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["AltitudeHold", "AltitudeHoldConfig"]


@dataclass(frozen=True)
class AltitudeHoldConfig:
    """The plan's ``[altitude_hold]`` table (gains in PWM per m, per m·s, per m/s)."""

    variable: str = "stateEstimate.z"  # log variable, m
    target_m: float = 1.0
    kp: float = 4000.0
    ki: float = 1500.0
    kd: float = 4000.0
    max_trim: int = 12000  # PWM
    kinds: tuple[str, ...] = ("hover", "excitation")


class AltitudeHold:
    """The PID above; call :meth:`update` once per setpoint tick."""

    def __init__(self, config: AltitudeHoldConfig, *, period_s: float) -> None:
        self.config = config
        self.period_s = period_s
        self.reset()

    def reset(self) -> None:
        self._integral = 0.0
        self._z_prev: float | None = None
        self._vz = 0.0
        self.trim = 0

    def update(self, *, z: float | None, active: bool) -> int:
        """Thrust trim (PWM) for this tick; 0 when inactive or before the first altitude sample."""
        c = self.config
        if not active or z is None or not math.isfinite(z):
            if not active:
                self.reset()
            return self.trim if active else 0
        h = self.period_s
        if self._z_prev is not None:
            self._vz += 0.5 * ((z - self._z_prev) / h - self._vz)
        self._z_prev = z
        error = c.target_m - z
        half = c.max_trim / 2
        self._integral = min(max(self._integral + c.ki * error * h, -half), half)
        raw = c.kp * error + self._integral - c.kd * self._vz
        self.trim = round(min(max(raw, -c.max_trim), c.max_trim))
        return self.trim
