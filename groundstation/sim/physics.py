"""Rigid-body physics of a Crazyflie 2.1: 6 degrees of freedom, motors, rotor drag, ground, battery.

Frames: world ``(x, y, z)`` with ``z`` up; body ``x`` forward (between M1 and M4), ``y`` left,
``z`` up. Attitude is the unit quaternion ``q = (w, x, y, z)`` rotating body vectors into the world.

Equations (one explicit step of ``dt`` seconds, semi-implicit Euler):

* Motor ``i`` thrust follows its target with a first-order lag,
  ``f_i += (f_i* - f_i) * dt / tau_m``, where the target is the firmware's cubic
  ``f* = c0 + c1 v + c2 v^2 + c3 v^3`` (N) in the motor voltage ``v = vbat * pwm / 65535``.
* Body force ``F_b = (0, 0, sum f_i) - k_d * (sum f_i / (m g)) * v_b`` (linear rotor drag, which
  is what makes the body-frame accelerometer x/y carry signal in flight).
* Torques from the motor positions (M1 front-right, M2 back-right, M3 back-left, M4 front-left,
  each at ``(+-l, +-l)``) and the propeller reaction torque ``k_tau * f_i`` (M1, M3 turn CCW
  seen from above, so they push the body clockwise):
  ``tau = (l (-f1 - f2 + f3 + f4), l (-f1 + f2 + f3 - f4), k_tau (-f1 + f2 - f3 + f4))``.
* ``m dv/dt = R F_b - m g e_z``; ``J dw/dt = tau - w x J w``; ``dq/dt = q * (0, w) / 2``.
* Ground: ``z >= 0``. While the thrust cannot lift the vehicle it rests level on the ground with
  zero velocity and zero body rates (friction).
* Battery: open-circuit voltage linear in the state of charge, minus ``R_int * I`` where the
  current is ``I = I_idle + k_I * sum(duty_i ** 1.5)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["GRAVITY_M_S2", "Battery", "RigidBody", "VehicleConstants", "motor_thrust_n"]

GRAVITY_M_S2 = 9.81
"""Standard gravity, m/s²."""


@dataclass(frozen=True)
class VehicleConstants:
    """Physical constants of a Crazyflie 2.1 (SI units; see docs/simulator.md for sources)."""

    mass_kg: float = 0.028
    arm_m: float = 0.031                       # motor offset along body x and y, m
    ixx_kg_m2: float = 1.66e-5
    iyy_kg_m2: float = 1.67e-5
    izz_kg_m2: float = 2.93e-5
    thrust_c0_n: float = -0.024765            # thrust cubic in motor voltage v (V) -> N
    thrust_c1_n_per_v: float = 0.065238
    thrust_c2_n_per_v2: float = -0.026793
    thrust_c3_n_per_v3: float = 0.0067768
    yaw_torque_m: float = 0.0069929           # reaction torque per newton of thrust, N m / N
    motor_tau_s: float = 0.03                  # first-order motor lag
    drag_kg_s: float = 0.012                   # linear rotor drag at hover thrust, N / (m/s)
    angular_drag_n_m_s: float = 2.0e-7         # small body-rate damping, N m / (rad/s)
    battery_capacity_c: float = 250e-3 * 3600  # 250 mAh in coulomb
    battery_empty_v: float = 3.0               # open-circuit voltage at 0 % charge
    battery_r_ohm: float = 0.13                # internal resistance incl. connectors
    battery_idle_a: float = 0.10               # electronics, radio
    battery_k_a: float = 1.0                   # motor current per duty**1.5


def motor_thrust_n(*, pwm: float, vbat_v: float, c: VehicleConstants) -> float:
    """Steady-state thrust (N) of one motor at ``pwm`` (0..65535) and battery voltage ``vbat_v``.

    ``f = c0 + c1 v + c2 v^2 + c3 v^3`` with ``v = vbat * pwm / 65535``, clipped at 0 N.
    """
    v = vbat_v * pwm / 65535.0
    f = c.thrust_c0_n + v * (c.thrust_c1_n_per_v + v * (c.thrust_c2_n_per_v2
                                                        + v * c.thrust_c3_n_per_v3))
    return f if f > 0.0 else 0.0


class Battery:
    """A LiPo cell with linear open-circuit voltage and an internal resistance (volts, amperes)."""

    def __init__(self, *, full_v: float, c: VehicleConstants) -> None:
        self.full_v = full_v
        self.c = c
        self.charge = 1.0          # state of charge, 0..1
        self.current_a = c.battery_idle_a
        self.voltage_v = full_v - c.battery_r_ohm * self.current_a

    def update(self, *, duties: tuple[float, float, float, float], dt_s: float) -> float:
        """Draw the current for motor ``duties`` (0..1 each) for ``dt_s``; return the terminal V."""
        c = self.c
        d1, d2, d3, d4 = duties
        i = c.battery_idle_a + c.battery_k_a * (d1 * math.sqrt(d1) + d2 * math.sqrt(d2)
                                                + d3 * math.sqrt(d3) + d4 * math.sqrt(d4))
        self.current_a = i
        self.charge = max(0.0, self.charge - i * dt_s / c.battery_capacity_c)
        ocv = c.battery_empty_v + (self.full_v - c.battery_empty_v) * self.charge
        self.voltage_v = ocv - c.battery_r_ohm * i
        return self.voltage_v


class RigidBody:
    """State and 1 kHz integration of the airframe; every field is a plain float (SI units)."""

    def __init__(self, *, c: VehicleConstants) -> None:
        self.c = c
        self.x = self.y = self.z = 0.0               # position, m (world)
        self.vx = self.vy = self.vz = 0.0            # velocity, m/s (world)
        self.qw, self.qx, self.qy, self.qz = 1.0, 0.0, 0.0, 0.0
        self.p = self.q = self.r = 0.0               # body rates, rad/s
        self.f1 = self.f2 = self.f3 = self.f4 = 0.0  # motor thrusts, N
        self.sfx = self.sfy = 0.0                    # specific force, body, m/s²
        self.sfz = GRAVITY_M_S2
        self.on_ground = True

    def euler_deg(self) -> tuple[float, float, float]:
        """Right-handed (roll, pitch, yaw) in degrees, ZYX convention (pitch > 0: nose down)."""
        w, x, y, z = self.qw, self.qx, self.qy, self.qz
        roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
        s = 2.0 * (w * y - z * x)
        pitch = math.asin(1.0 if s > 1.0 else -1.0 if s < -1.0 else s)
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        return math.degrees(roll), math.degrees(pitch), math.degrees(yaw)

    def step(self, t1: float, t2: float, t3: float, t4: float, dt: float, /) -> None:
        """Advance ``dt`` seconds with motor thrust targets ``t1..t4`` (N).

        Positional-only: this is the 1 kHz inner loop, keyword passing costs measurable time.
        """
        c = self.c
        a = dt / c.motor_tau_s
        f1 = self.f1 + (t1 - self.f1) * a
        f2 = self.f2 + (t2 - self.f2) * a
        f3 = self.f3 + (t3 - self.f3) * a
        f4 = self.f4 + (t4 - self.f4) * a
        self.f1, self.f2, self.f3, self.f4 = f1, f2, f3, f4
        ft = f1 + f2 + f3 + f4
        m = c.mass_kg
        w, x, y, z = self.qw, self.qx, self.qy, self.qz
        # Rotation matrix body -> world.
        r00 = 1.0 - 2.0 * (y * y + z * z)
        r01 = 2.0 * (x * y - w * z)
        r02 = 2.0 * (x * z + w * y)
        r10 = 2.0 * (x * y + w * z)
        r11 = 1.0 - 2.0 * (x * x + z * z)
        r12 = 2.0 * (y * z - w * x)
        r20 = 2.0 * (x * z - w * y)
        r21 = 2.0 * (y * z + w * x)
        r22 = 1.0 - 2.0 * (x * x + y * y)
        vx, vy, vz = self.vx, self.vy, self.vz
        # Velocity in the body frame, rotor drag proportional to total thrust.
        kd = c.drag_kg_s * ft / (m * GRAVITY_M_S2)
        fbx = -kd * (r00 * vx + r10 * vy + r20 * vz)
        fby = -kd * (r01 * vx + r11 * vy + r21 * vz)
        fbz = ft - kd * (r02 * vx + r12 * vy + r22 * vz)
        ax = (r00 * fbx + r01 * fby + r02 * fbz) / m
        ay = (r10 * fbx + r11 * fby + r12 * fbz) / m
        az = (r20 * fbx + r21 * fby + r22 * fbz) / m - GRAVITY_M_S2
        if self.on_ground and az <= 0.0:
            # Resting: the ground supplies the missing force; level, no motion.
            self.vx = self.vy = self.vz = 0.0
            self.p = self.q = self.r = 0.0
            n = math.hypot(w, z)
            self.qw, self.qx, self.qy, self.qz = w / n, 0.0, 0.0, z / n
            self.z = 0.0
            self.sfx, self.sfy, self.sfz = 0.0, 0.0, GRAVITY_M_S2
            return
        self.sfx, self.sfy, self.sfz = fbx / m, fby / m, fbz / m
        vx += ax * dt
        vy += ay * dt
        vz += az * dt
        self.x += vx * dt
        self.y += vy * dt
        zz = self.z + vz * dt
        if zz <= 0.0:
            zz = 0.0
            self.on_ground = True
            vx = vy = vz = 0.0
        else:
            self.on_ground = False
        self.z = zz
        self.vx, self.vy, self.vz = vx, vy, vz
        # Rotational dynamics.
        arm = c.arm_m
        p, q, r = self.p, self.q, self.r
        ixx, iyy, izz = c.ixx_kg_m2, c.iyy_kg_m2, c.izz_kg_m2
        cd = c.angular_drag_n_m_s
        tx = arm * (-f1 - f2 + f3 + f4) - cd * p
        ty = arm * (-f1 + f2 + f3 - f4) - cd * q
        tz = c.yaw_torque_m * (-f1 + f2 - f3 + f4) - cd * r
        p += (tx - (izz - iyy) * q * r) / ixx * dt
        q += (ty - (ixx - izz) * p * r) / iyy * dt
        r += (tz - (iyy - ixx) * p * q) / izz * dt
        self.p, self.q, self.r = p, q, r
        h = 0.5 * dt
        nw = w - h * (x * p + y * q + z * r)
        nx = x + h * (w * p + y * r - z * q)
        ny = y + h * (w * q - x * r + z * p)
        nz = z + h * (w * r + x * q - y * p)
        n = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        self.qw, self.qx, self.qy, self.qz = nw * n, nx * n, ny * n, nz * n
