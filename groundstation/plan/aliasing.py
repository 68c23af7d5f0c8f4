"""Aliased motor logs: the check ``plan design`` runs on flown sessions (``docs/flightplans.md``).

The firmware's attitude PID runs at 500 Hz, but with the Kalman estimator the attitude it
controls changes only at the estimator's 100 Hz. A D term on an attitude axis
(``pid_attitude.yaw_kd = 0.35`` by default) differentiates those steps into a one-tick pulse of
the motor commands every 10 ms, proportional to the rate. A 50 Hz log block samples the motors
at a phase that drifts against those pulses, so the logged motor commands of that axis carry
pulses at random: broadband noise on the identification's input, largest in the top of the
band, where the vehicle's rates (low-passed by the motors and the inertia) carry almost none.
No excitation fixes that; a flight without the D term does (the rate loop and the attitude P and
I terms stay). The check therefore needs both: a top-band share above :data:`ALIAS_SHARE` and
a D term in the flown firmware (an axis that is hardly excited has a large share of noise in
its top band, but without a D term nothing is aliased).

A log locked in phase to the estimator's steps is not detected: every sample then hits (or
misses) the pulses alike, a bias that follows the rate rather than broadband noise
(``docs/flightplans.md``, "Aliased motor logs").

An axis' motor combination is the legacy mixer's column (``m1 = T - r/2 + p/2 + y``, ...).
Its *top-band share* is the part of its power (Welch periodogram, mean removed) above 2/3 of
the log's Nyquist frequency. Measured on 40 s PRBS flights of the real firmware in the loop:
yaw 19-33 % per flight with the D term and 0.1 % without; roll and pitch (no D term) 2-12 % when
excited, about 35 % on a yaw-only flight. ``sim://`` with the Kalman estimator
(``stabilizer.estimator = 2``, as the firmware in the loop) yaw 10-12 %, 0.04-0.07 % without the D
term; with its default complementary estimator (the attitude at every controller tick) 0.7-1.0 %.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from groundstation.plan import Plan

__all__ = ["ALIAS_SHARE", "D_TERM", "MIXER", "MOTOR_INPUTS", "axis_shares", "d_term_changes",
           "top_band_share"]

MOTOR_INPUTS = ("motor.m1", "motor.m2", "motor.m3", "motor.m4")
MIXER = {"roll": (-1.0, -1.0, 1.0, 1.0), "pitch": (1.0, -1.0, -1.0, 1.0),
         "yaw_rate": (1.0, -1.0, 1.0, -1.0)}
"""Each setpoint axis' column of the firmware's legacy mixer over motor.m1..m4 (signs only)."""
D_TERM = {"roll": "pid_attitude.roll_kd", "pitch": "pid_attitude.pitch_kd",
          "yaw_rate": "pid_attitude.yaw_kd"}
"""The attitude PID's D gain of each axis (firmware parameter)."""
TOP_BAND = 2.0 / 3.0  # of the Nyquist frequency
ALIAS_SHARE = 0.05
"""Above this top-band share (with a D term) a motor combination is aliased: a quarter of the
smallest share measured with the D term on the firmware in the loop (18.6 %, the mean of two
flights), 50 times the largest of a D term that aliases nothing (``sim://``, 0.1 %)."""
_SEGMENT = 256


def top_band_share(x: np.ndarray) -> float:
    """Share of the power of ``x`` (N,) above :data:`TOP_BAND` of the Nyquist frequency:
    averaged periodograms of 256-sample Hann-windowed segments, half overlapping, mean
    removed. NaN for fewer than 256 samples or a constant signal."""
    x = np.asarray(x, dtype=float)
    if x.size < _SEGMENT:
        return float("nan")
    win = np.hanning(_SEGMENT)
    starts = range(0, x.size - _SEGMENT + 1, _SEGMENT // 2)
    power = sum(np.abs(np.fft.rfft((x[s:s + _SEGMENT] - x[s:s + _SEGMENT].mean()) * win)) ** 2
                for s in starts)
    total = float(np.sum(power[1:]))
    if not total > 0:
        return float("nan")
    freq = np.fft.rfftfreq(_SEGMENT)  # cycles per sample; Nyquist 0.5
    return float(np.sum(power[freq > TOP_BAND * 0.5]) / total)


def axis_shares(u: Sequence[np.ndarray], *, input_names: Sequence[str]) -> dict[str, float]:
    """Top-band share of each axis' motor combination, pooled over flights ``u`` ((N, m)
    each, columns named by ``input_names``); empty unless the inputs include
    ``motor.m1..m4``."""
    names = list(input_names)
    if not set(MOTOR_INPUTS) <= set(names):
        return {}
    cols = [names.index(n) for n in MOTOR_INPUTS]
    out = {}
    for axis, column in MIXER.items():
        shares = [top_band_share(np.asarray(x, dtype=float)[:, cols] @ np.array(column))
                  for x in u]
        shares = [s for s in shares if np.isfinite(s)]
        if shares:
            out[axis] = float(np.mean(shares))
    return out


def d_term_changes(plan: Plan, *, aliasing: Mapping[str, float], firmware: Mapping[str, float]
                   ) -> list[tuple[tuple[str, ...], float, Any, str]]:
    """``(path, value, old, why)`` for the plan's ``[parameters]``: the attitude D term at 0 on
    every axis the plan excites whose motor combination was aliased (``aliasing``: top-band
    shares, :func:`axis_shares`) while the flown firmware (``firmware``: ``group.name`` ->
    value) had that D term; nothing for an axis the plan already flies without it."""
    excited = {e.axis for p in plan.phases for e in p.excitation if e.signal == "prbs"}
    planned = dict(plan.parameters)
    out = []
    for axis in MIXER:
        share, param = aliasing.get(axis), D_TERM[axis]
        kd = planned.get(param, firmware.get(param))
        if axis not in excited or share is None or not share > ALIAS_SHARE or not kd:
            continue
        out.append((("parameters", *param.split(".")), 0.0, kd,
                    f"the motors' {axis} combination had {100 * share:.1f} % of its power in the "
                    f"top third of the log's band (aliased above {100 * ALIAS_SHARE:g} %): the "
                    "attitude D term turns the estimator's 100 Hz steps into motor pulses the "
                    "log samples at random; 0 for this flight, restored after it"))
    return out
