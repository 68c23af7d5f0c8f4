"""The physics side of the real firmware in the loop: our vehicle model, its sensor packets.

:class:`PhysicsPeer` is the part of CrazySim's Gazebo plugin that the SITL firmware needs (see
``shared/sitl/README.md``), built from the same code as ``sim://``: the rigid body and battery of
:mod:`groundstation.sim.physics` and the noisy BMI088 model of :mod:`groundstation.sim.sensors`.
No sockets here: :mod:`groundstation.sim.sitl` feeds it the firmware's motor commands and sends
what it returns. One call of :meth:`PhysicsPeer.step` is one millisecond of vehicle time and
yields the 1 kHz IMU packet; :meth:`barometer_packet` (50 Hz), :meth:`pose_packet` (200 Hz,
the external pose a motion-capture system would send) and :meth:`battery_packet` (10 Hz) are due
every ``BARO_EVERY``, ``POSE_EVERY`` and ``BATTERY_EVERY`` steps.

Wire formats (little-endian, the header byte first, ``(port << 4) | (3 << 2) | channel``):

* IMU: port 9 channel 0, ``<B B 3h 3h``: type 0, specific force in the body frame (x forward,
  y left, z up) in 1/2048 g, body rates in 4000/65536 deg/s.
* Barometer: port 9 channel 0, ``<B B 3f``: type 2, pressure (mbar), temperature (deg C),
  altitude (m).
* Battery: port 9 channel 0, ``<B B f``: type 3, voltage (V). Not CrazySim's: the project's
  firmware patch ``tools/sitl-pm-battery.patch`` adds it with the ``pm`` log group (``vbat``,
  ``vbatMV``, ``state``, ``batteryLevel``) that the SITL build otherwise lacks; the firmware's
  control loop does not step on it.
* External pose: port 6 channel 1, ``<B B 7f``: id 8, x, y, z (m), qx, qy, qz, qw.
* Motor command from the firmware: port 9 channel 0, ``<B 4H``, m1..m4 PWM (0..65535), what the
  firmware logs as ``motor.m1..m4``.

Motor commands become duty cycles as on a Crazyflie 2.x: its firmware scales each command by
the battery voltage (``motorsCompensateBatteryVoltage`` in ``motors.c``) after the mixer, a
hardware-driver stage the SITL build leaves out. The peer applies it with the ``sim://``
firmware's own :func:`~groundstation.sim.firmware.battery_compensated_pwm`, so a motor command
gives the thrust it gives on ``sim://`` and on a real vehicle: independent of the battery's
charge and sag. Without it the command was the duty, the thrust fell with the battery and the
motor-to-rate gain at hover was 1.5 times ``sim://``'s.
"""

from __future__ import annotations

import math
import random
import struct

from groundstation.sim.crtp_wire import crtp_channel, crtp_header, crtp_port
from groundstation.sim.firmware import battery_compensated_pwm
from groundstation.sim.physics import (
    GRAVITY_M_S2,
    Battery,
    RigidBody,
    VehicleConstants,
    motor_thrust_n,
)
from groundstation.sim.sensors import NoiseModel, Sensors

__all__ = [
    "BARO_EVERY",
    "BATTERY_EVERY",
    "GYRO_BIAS_FOUND",
    "POSE_EVERY",
    "PhysicsPeer",
    "crtp_header",
    "parse_motor_packet",
]

DT_S = 0.001
BARO_EVERY = 20        # steps (ms) between barometer packets: 50 Hz
POSE_EVERY = 5         # steps (ms) between external-pose packets: 200 Hz
BATTERY_EVERY = 100    # steps (ms) between battery packets: 10 Hz
ACC_LSB_PER_G = 2048.0            # ±16 g range
GYRO_LSB_PER_DPS = 65536.0 / 4000.0  # ±2000 deg/s range

_SIM_PORT, _SIM_CHANNEL = 9, 0
SIM_HEADER = crtp_header(port=_SIM_PORT, channel=_SIM_CHANNEL)
"""Port 9 (``CRTP_PORT_SETPOINT_SIM``) channel 0: sensors in, motors out."""
_POSE_HEADER = crtp_header(port=6, channel=1)
_EXT_POSE_ID = 8
_IMU = struct.Struct("<BB3h3h")
_BARO = struct.Struct("<BB3f")
_POSE = struct.Struct("<BB7f")
_BATTERY = struct.Struct("<BBf")
_MOTORS = struct.Struct("<B4H")
GYRO_BIAS_FOUND = bytes([SIM_HEADER, 1])
"""What the firmware sends once its gyro bias estimate is done (``9c 01``)."""


def parse_motor_packet(data: bytes) -> tuple[int, int, int, int] | None:
    """m1..m4 PWM of a motor-command datagram, or ``None`` if ``data`` is something else."""
    if (len(data) != _MOTORS.size or crtp_port(data[0]) != _SIM_PORT
            or crtp_channel(data[0]) != _SIM_CHANNEL):  # the link bits may be anything
        return None
    _, m1, m2, m3, m4 = _MOTORS.unpack(data)
    return (m1, m2, m3, m4)


def _i16(x: float) -> int:
    return -32768 if x < -32768.0 else 32767 if x > 32767.0 else round(x)


class PhysicsPeer:
    """One simulated airframe driven by the real firmware's motor commands (SI units inside).

    ``const`` and ``noise`` default to the ``sim://`` vehicle's; ``seed`` fixes the noise.
    Not thread-safe: one thread calls :meth:`set_motors` and :meth:`step`.
    """

    def __init__(self, *, seed: int = 0, vbat_full: float = 4.15,
                 const: VehicleConstants | None = None, noise: NoiseModel | None = None) -> None:
        self.const = const or VehicleConstants()
        rng = random.Random(seed)
        self.body = RigidBody(c=self.const)
        self.battery = Battery(full_v=vbat_full, c=self.const)
        self.sensors = Sensors(rng=rng, noise=noise, rate_hz=1.0 / DT_S)  # the IMU's 1 kHz
        self.pwm: tuple[int, int, int, int] = (0, 0, 0, 0)   # the firmware's motor commands
        self.duty_pwm: tuple[int, int, int, int] = (0, 0, 0, 0)  # after battery compensation
        self.steps = 0
        self._targets = (0.0, 0.0, 0.0, 0.0)

    @property
    def time_s(self) -> float:
        """Vehicle time: steps taken, in seconds."""
        return self.steps * DT_S

    def set_motors(self, pwm: tuple[int, int, int, int]) -> None:
        """The firmware's latest motor command (held until the next one), battery-compensated at
        the present voltage as the real firmware does."""
        self.pwm = pwm
        vbat = self.battery.voltage_v
        c = self.const
        duty = [battery_compensated_pwm(ithrust=p, vbat_v=vbat) if p else 0 for p in pwm]
        self.duty_pwm = (duty[0], duty[1], duty[2], duty[3])
        t = [motor_thrust_n(pwm=d, vbat_v=vbat, c=c) for d in duty]
        self._targets = (t[0], t[1], t[2], t[3])

    def step(self) -> bytes:
        """Advance one millisecond; return the IMU packet sampled at its end."""
        t1, t2, t3, t4 = self._targets
        body = self.body
        body.step(t1, t2, t3, t4, DT_S)
        p = self.duty_pwm
        duties = (p[0] / 65535.0, p[1] / 65535.0, p[2] / 65535.0, p[3] / 65535.0)
        self.battery.update(duties=duties, dt_s=DT_S)
        s = self.sensors
        s.sample(body=body, duty=sum(duties) / 4.0)
        self.steps += 1
        return _IMU.pack(SIM_HEADER, 0,
                         _i16(s.ax * ACC_LSB_PER_G), _i16(s.ay * ACC_LSB_PER_G),
                         _i16(s.az * ACC_LSB_PER_G),
                         _i16(s.gx * GYRO_LSB_PER_DPS), _i16(s.gy * GYRO_LSB_PER_DPS),
                         _i16(s.gz * GYRO_LSB_PER_DPS))

    def barometer_packet(self) -> bytes:
        """Pressure (ISA troposphere, sea level at the take-off point), 25 deg C, altitude."""
        z = self.body.z
        pressure_mbar = 1013.25 * (1.0 - 2.25577e-5 * z) ** 5.25588
        return _BARO.pack(SIM_HEADER, 2, pressure_mbar, 25.0, z)

    def battery_packet(self) -> bytes:
        """The battery voltage under the present load (V), for the firmware's ``pm`` group."""
        return _BATTERY.pack(SIM_HEADER, 3, self.battery.voltage_v)

    def pose_packet(self) -> bytes:
        """The external pose (position m, attitude quaternion body -> world)."""
        b = self.body
        return _POSE.pack(_POSE_HEADER, _EXT_POSE_ID, b.x, b.y, b.z, b.qx, b.qy, b.qz, b.qw)

    def hover_pwm(self) -> int:
        """The motor command that carries the weight (the same at any battery voltage until the
        compensation saturates)."""
        c, vbat = self.const, self.battery.voltage_v
        weight = c.mass_kg * GRAVITY_M_S2 / 4.0
        lo, hi = 0.0, 65535.0
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            duty = battery_compensated_pwm(ithrust=mid, vbat_v=vbat)
            if motor_thrust_n(pwm=duty, vbat_v=vbat, c=c) < weight:
                lo = mid
            else:
                hi = mid
        return math.ceil(hi)
