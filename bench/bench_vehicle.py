"""Speed of SimVehicle.advance: 1 kHz steps per second, as a real-time factor (target >= 20x).

Baseline measured in the same run: a plain Python loop of the same length doing one float
multiply-add per step, so the "steps cost N loop iterations" figure means the same on any machine.
"""

from __future__ import annotations

import time

from groundstation.sim.vehicle import SimVehicle

TARGET_REALTIME_FACTOR = 20.0
_SIM_S = 10.0


def _hover_run() -> float:
    """Wall seconds to simulate _SIM_S of hover with 10 Hz setpoints (setpoint cost included)."""
    v = SimVehicle(seed=0, start_z_m=0.5)
    v.commander_rpyt(roll=0.0, pitch=0.0, yawrate=0.0, thrust=0)
    h = v.hover_thrust()
    t0 = time.perf_counter()
    for _ in range(round(_SIM_S * 10)):
        v.commander_rpyt(roll=0.0, pitch=-2.0, yawrate=5.0, thrust=h)
        v.advance(0.1)
    return time.perf_counter() - t0


def _baseline(n: int) -> float:
    t0 = time.perf_counter()
    x = 0.0
    for _ in range(n):
        x = x * 0.5 + 1.0
    return time.perf_counter() - t0


def main() -> int:
    steps = round(_SIM_S * 1000)
    wall = min(_hover_run() for _ in range(3))
    base = min(_baseline(steps) for _ in range(3))
    rate = steps / wall
    rtf = _SIM_S / wall
    print(f"SimVehicle.advance: {rate:,.0f} steps/s = {rtf:.1f}x real time "
          f"(target >= {TARGET_REALTIME_FACTOR:.0f}x); {wall / steps * 1e6:.1f} us per 1 kHz step")
    print(f"one step costs {wall / base:.0f}x a bare Python loop iteration (baseline, same run)")
    return 0 if rtf >= TARGET_REALTIME_FACTOR else 1
