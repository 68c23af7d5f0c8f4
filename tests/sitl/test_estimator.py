"""The real firmware's attitude estimate follows our vehicle beyond |yaw| = 90 deg.

The physics peer sends the external pose (position and attitude, as a motion-capture system
would) and the SITL build's Kalman filter fuses it. The pinned firmware computed the attitude
residual of that fusion in the world frame and applied it to body-frame states
(bitcraze/crazyflie-firmware#1292, fixed upstream by #1531): right at yaw 0, wrong beyond
|yaw| = 90 deg, where roll and pitch made the estimate run away and the vehicle flipped (the
thesis' identification plan drifts there after about 20 s of its yaw-rate PRBS).
``tools/sitl-kalman-pose-residual.patch`` backports the fix.

Procedure (about 13 s): take off, turn by about 160 deg of yaw, then alternate roll and pitch
setpoints of +-20 deg every 0.25 s for 3 s, then hover level. The physics' true attitude is
sampled at every setpoint; the firmware's estimate (``stateEstimate.*``) is logged at 100 Hz.
Measured without the fix: the vehicle reached 140 deg of tilt and fell. With it: at most 17 deg
of tilt, and the final estimate within 0.11 deg of the truth (3 runs).
"""

from __future__ import annotations

import math
import time

import numpy as np

from groundstation.flight.clock import clock_for_uri

from ..sim_crtp.helpers import Recorder, connect
from . import backend

RATE_HZ = 50.0
ESTIMATE = {"est": ["stateEstimate.roll", "stateEstimate.pitch", "stateEstimate.yaw"]}


def _tilt_deg(roll: float, pitch: float) -> float:
    return math.degrees(math.acos(math.cos(math.radians(roll)) * math.cos(math.radians(pitch))))


def test_attitude_estimate_follows_the_vehicle_beyond_90_deg_of_yaw():
    try:
        v = backend.start_vehicle()
        hover = v.peer.hover_pwm()
        # (seconds, roll deg, pitch deg, yaw rate deg/s, thrust) for each setpoint segment
        plan = [(1.2, 0.0, 0.0, 0.0, hover + 6000), (1.5, 0.0, 0.0, 100.0, hover),
                (0.5, 0.0, 0.0, 0.0, hover)]
        tilts = [(20.0, 0.0), (0.0, 20.0), (-20.0, 0.0), (0.0, -20.0)]
        plan += [(0.25, *tilts[k % 4], 0.0, hover + 3000) for k in range(12)]
        plan += [(1.5, 0.0, 0.0, 0.0, hover)]
        clock = clock_for_uri(v.uri)
        truth: list[tuple[str, float, float, float, float]] = []   # phase, roll, pitch, yaw, z
        with connect(v.uri, toc_cache=True) as scf:
            cf = scf.cf
            rec = Recorder(cf, blocks=ESTIMATE, period_ms=10)
            cf.commander.send_setpoint(0, 0, 0, 0)  # release the thrust lock
            t = clock.now()
            for i, (duration, roll, pitch, yaw_rate, thrust) in enumerate(plan):
                phase = "tilt" if roll or pitch else "end" if i == len(plan) - 1 else "turn"
                for _ in range(round(duration * RATE_HZ)):
                    cf.commander.send_setpoint(roll, pitch, yaw_rate, thrust)
                    t += 1.0 / RATE_HZ
                    clock.sleep_until(t)
                    body = v.peer.body
                    truth.append((phase, *body.euler_deg(), body.z))
            cf.commander.send_stop_setpoint()
            time.sleep(0.1)
            _, est = rec.rows("est")
    finally:
        backend.close_all()
    tilt = [(_tilt_deg(r, p), y, z) for phase, r, p, y, z in truth if phase == "tilt"]
    assert abs(tilt[0][1]) > 100.0, "the turn did not reach the bug's region"
    worst = max(a for a, _, _ in tilt)
    assert worst < 45.0, f"the vehicle lost its attitude: {worst:.0f} deg of tilt"
    assert min(z for _, _, z in tilt) > 0.2, "the vehicle touched the ground while tilting"
    # At the end (1.5 s level hover) the estimate is the truth: roll, legacy pitch, yaw.
    _, roll, pitch, yaw, _ = truth[-1]
    err = est[-1] - np.array([roll, -pitch, yaw])
    err[2] = (err[2] + 180.0) % 360.0 - 180.0
    assert np.all(np.abs(err) < 3.0), (est[-1], (roll, -pitch, yaw))
