"""Simulated BMI088 gyro and accelerometer: body frame, noise, residual bias, motor vibration.

Model, per axis ``k`` and sample (500 Hz, the controller's rate):

``gyro_k = omega_k + b_k + (s_g0,k + s_gv,k * d^2) * n``  (deg/s),
``acc_k = f_k / g + a_k + (s_a0,k + s_av,k * d^2) * n``  (g),

with ``omega`` the body rates, ``f`` the specific force in the body frame, ``b``/``a`` small biases
drawn once at power-on (what remains after the firmware's gyro calibration), ``d`` the mean motor
duty (0..1), ``n`` standard normal noise: the raw samples, before the firmware's sensor
filters (:class:`groundstation.sim.firmware.ImuFilter`, gyro 80 Hz, acc 30 Hz). The rest and
vibration terms are calibrated so that a simulated hover, *after* those filters, shows the
standard deviations measured on the real hover of ``shared/data/crazypad`` (see
docs/simulator.md and :data:`HOVER_GYRO_STD_DPS`, :data:`HOVER_ACC_STD_G`).
"""

from __future__ import annotations

import dataclasses
import math
import random
from dataclasses import dataclass

import numpy as np

from groundstation.sim.physics import GRAVITY_M_S2, RigidBody

__all__ = [
    "HOVER_ACC_STD_G",
    "HOVER_GYRO_STD_DPS",
    "NOISE_RATE_HZ",
    "NoiseModel",
    "Sensors",
    "hover_noise_std",
]

NOISE_RATE_HZ = 500.0
"""Sample rate the levels of :class:`NoiseModel` are given at (the emulated firmware's)."""
HOVER_GYRO_STD_DPS = (1.97, 1.27, 0.33)
"""Calibration target: hover noise std of gyro x, y, z (deg/s) on the real CF2.1 (CrazyPAD E8).

Median over the four hover segments of ``controller_E8_log00/01`` of :func:`hover_noise_std` of
``controller.r_roll/r_pitch/r_yaw``; see docs/simulator.md."""
HOVER_ACC_STD_G = (0.0076, 0.0101, 0.0084)
"""Calibration target: hover noise std of acc x, y, z (g). z from ``controller.accelz``; x and y
from ``stateEstimate.ax/ay`` of ``motor_E8_log00`` (the logs carry no body acc.x/y)."""


def hover_noise_std(x: np.ndarray, *, window: int = 10) -> float:
    """The noise metric of the calibration: std of ``x`` (n,) minus its centred moving mean.

    ``x`` is sampled at 100 Hz; ``window = 10`` removes everything slower than about 10 Hz (the
    closed-loop motion), leaving sensor noise and motor vibration. The first and last
    ``window`` samples are dropped (edge effects).
    """
    x = np.asarray(x, dtype=np.float64)
    smooth = np.convolve(x, np.ones(window) / window, mode="same")
    return float(np.std((x - smooth)[window:-window]))


@dataclass(frozen=True)
class NoiseModel:
    """Per-axis (x, y, z) noise std: ``*_rest`` with motors off, ``*_vib`` added at full duty.

    The total std at mean duty ``d`` is ``rest + vib * d^2``, of the raw 500 Hz samples. Rest
    levels are fitted so the filtered samples show the real vehicle's before take-off; vibration
    levels so a simulated, filtered hover matches the targets.
    """

    gyro_rest_dps: tuple[float, float, float] = (0.167, 0.278, 0.184)
    gyro_vib_dps: tuple[float, float, float] = (7.75, 4.55, 1.12)
    acc_rest_g: tuple[float, float, float] = (0.0036, 0.0038, 0.0039)
    acc_vib_g: tuple[float, float, float] = (0.0512, 0.0722, 0.0598)
    gyro_bias_dps: float = 0.1
    acc_bias_g: float = 0.003


class Sensors:
    """Holds the latest raw gyro (deg/s) and accelerometer (g) sample, taken at ``rate_hz``
    (the noise levels of ``noise`` are those of :data:`NOISE_RATE_HZ` samples)."""

    _BLOCK = 6 * 4096   # normals drawn per numpy call (one list index per sample afterwards)

    def __init__(self, *, rng: random.Random, noise: NoiseModel | None = None,
                 rate_hz: float = NOISE_RATE_HZ) -> None:
        nm = noise or NoiseModel()
        # The levels are per sample at NOISE_RATE_HZ; sampled faster, the same noise density
        # (what the firmware's 80 Hz and 30 Hz filters pass on) has a larger per-sample std.
        k = math.sqrt(rate_hz / NOISE_RATE_HZ)
        self.noise = dataclasses.replace(
            nm, **{f: tuple(k * x for x in getattr(nm, f))
                   for f in ("gyro_rest_dps", "gyro_vib_dps", "acc_rest_g", "acc_vib_g")})
        self._np_rng = np.random.default_rng(rng.getrandbits(64))
        self._normals: list[float] = []
        self._k = 0
        self.bias_g = tuple(rng.gauss(0.0, nm.gyro_bias_dps) for _ in range(3))
        self.bias_a = tuple(rng.gauss(0.0, nm.acc_bias_g) for _ in range(3))
        self.gx = self.gy = self.gz = 0.0
        self.ax = self.ay = 0.0
        self.az = 1.0

    def sample(self, *, body: RigidBody, duty: float) -> None:
        """Take one sample of the body's state with mean motor duty ``duty`` (0..1)."""
        nm = self.noise
        k0 = self._k
        if k0 + 6 > len(self._normals):
            self._normals = self._np_rng.standard_normal(self._BLOCK).tolist()
            k0 = 0
        self._k = k0 + 6
        n0, n1, n2, n3, n4, n5 = self._normals[k0:k0 + 6]
        d2 = duty * duty
        gr, gv, ar, av = nm.gyro_rest_dps, nm.gyro_vib_dps, nm.acc_rest_g, nm.acc_vib_g
        bg, ba = self.bias_g, self.bias_a
        k = 180.0 / math.pi
        self.gx = body.p * k + bg[0] + (gr[0] + gv[0] * d2) * n0
        self.gy = body.q * k + bg[1] + (gr[1] + gv[1] * d2) * n1
        self.gz = body.r * k + bg[2] + (gr[2] + gv[2] * d2) * n2
        ig = 1.0 / GRAVITY_M_S2
        self.ax = body.sfx * ig + ba[0] + (ar[0] + av[0] * d2) * n3
        self.ay = body.sfy * ig + ba[1] + (ar[1] + av[1] * d2) * n4
        self.az = body.sfz * ig + ba[2] + (ar[2] + av[2] * d2) * n5
