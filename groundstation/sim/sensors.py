"""Simulated BMI088 gyro and accelerometer: body frame, noise, residual bias, motor vibration.

Model, per axis ``k`` and sample (500 Hz, the controller's rate):

``gyro_k = omega_k + b_k + (s_g0 + s_gv * d^2) * n``  (deg/s),
``acc_k = f_k / g + a_k + (s_a0 + s_av * d^2) * n``  (g),

with ``omega`` the body rates, ``f`` the specific force in the body frame, ``b``/``a`` small biases
drawn once at power-on (what remains after the firmware's gyro calibration), ``d`` the mean motor
duty (0..1), ``n`` standard normal noise. The vibration terms are calibrated so that a simulated
hover shows the standard deviations measured on the real hover of ``shared/data/crazypad``
(see docs/simulator.md and :data:`HOVER_GYRO_STD_DPS`, :data:`HOVER_ACC_STD_G`).
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

from groundstation.sim.physics import GRAVITY_M_S2, RigidBody

__all__ = ["HOVER_ACC_STD_G", "HOVER_GYRO_STD_DPS", "NoiseModel", "Sensors"]

HOVER_GYRO_STD_DPS = (1.0, 1.0, 1.0)
"""Calibration target: std of gyro x, y, z (deg/s) in the real hover (see docs/simulator.md)."""
HOVER_ACC_STD_G = (0.01, 0.01, 0.01)
"""Calibration target: std of acc x, y, z (g) in the real hover (see docs/simulator.md)."""


@dataclass(frozen=True)
class NoiseModel:
    """Noise levels: ``*_rest`` with motors off, ``*_vib`` added at full duty (scales with d^2)."""

    gyro_rest_dps: float = 0.05
    gyro_vib_dps: float = 2.0
    acc_rest_g: float = 0.002
    acc_vib_g: float = 0.03
    gyro_bias_dps: float = 0.1
    acc_bias_g: float = 0.003
    hover_duty: float = 0.6


class Sensors:
    """Holds the latest gyro (deg/s) and accelerometer (g) sample."""

    def __init__(self, *, rng: random.Random, noise: NoiseModel | None = None) -> None:
        self.noise = noise or NoiseModel()
        self._gauss = rng.gauss
        nm = self.noise
        self.bias_g = tuple(rng.gauss(0.0, nm.gyro_bias_dps) for _ in range(3))
        self.bias_a = tuple(rng.gauss(0.0, nm.acc_bias_g) for _ in range(3))
        self.gx = self.gy = self.gz = 0.0
        self.ax = self.ay = 0.0
        self.az = 1.0

    def sample(self, *, body: RigidBody, duty: float) -> None:
        """Take one sample of the body's state with mean motor duty ``duty`` (0..1)."""
        nm = self.noise
        g = self._gauss
        d2 = duty * duty
        sg = nm.gyro_rest_dps + nm.gyro_vib_dps * d2
        sa = nm.acc_rest_g + nm.acc_vib_g * d2
        bg, ba = self.bias_g, self.bias_a
        k = 180.0 / math.pi
        self.gx = body.p * k + bg[0] + sg * g(0.0, 1.0)
        self.gy = body.q * k + bg[1] + sg * g(0.0, 1.0)
        self.gz = body.r * k + bg[2] + sg * g(0.0, 1.0)
        ig = 1.0 / GRAVITY_M_S2
        self.ax = body.sfx * ig + ba[0] + sa * g(0.0, 1.0)
        self.ay = body.sfy * ig + ba[1] + sa * g(0.0, 1.0)
        self.az = body.sfz * ig + ba[2] + sa * g(0.0, 1.0)
