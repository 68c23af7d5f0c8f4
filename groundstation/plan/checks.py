"""Warnings about a valid plan that is probably not the plan meant: longer than a battery
flies, a take-off or landing ramp of minutes (milliseconds typed as seconds), an attitude
amplitude as small as a value meant in radians. Nothing here refuses a plan (the loader's
checks do that); ``plan check`` and ``fly`` print these, each
``FILE:LINE: key.path: problem; what to do``.
"""

from __future__ import annotations

import math

from groundstation.plan import Plan
from groundstation.plan.toml import TomlSource

__all__ = ["RAMP_WARN_S", "plan_warnings"]

RAMP_WARN_S = 30.0
"""A take-off or landing longer than this, s, is warned about: the shipped plans ramp 2-3 s, so
30 s is ten times the longest, and a ramp meant in ms and typed as s (2000) is far beyond it."""

_LIMIT = {"roll": "max_roll_deg", "pitch": "max_pitch_deg", "yaw_rate": "max_yaw_rate_deg_s"}


def plan_warnings(plan: Plan) -> list[str]:
    """The plan's warnings (module docstring), in file order after the whole-plan one."""
    src = TomlSource(text=plan.text, source=plan.source)
    rate, out = plan.setpoint_rate_hz, []
    battery = plan.vehicle.flight_time_s
    if plan.duration > battery:
        i = max(range(len(plan.phases)), key=lambda k: plan.phases[k].n_ticks)
        longest = plan.phases[i].n_ticks / rate
        given = ("vehicle", "flight_time_s") in src.lines
        whose = ("" if given else
                 ", the default: about 7 minutes, Bitcraze's figure for a Crazyflie 2.x "
                 "on its stock battery")
        out.append(src.note(
            ("phase", i, "duration"),
            f"the plan flies {plan.duration:g} s ({plan.duration / 60:.1f} min), longer than "
            f"one battery lasts (vehicle.flight_time_s = {battery:g} s{whose}); shorten the "
            f"phases (this one, the longest, lasts {longest:g} s), or set "
            "vehicle.flight_time_s for a bigger battery"))
    for i, phase in enumerate(plan.phases):
        seconds = phase.n_ticks / rate
        if phase.kind in ("takeoff", "landing") and seconds > RAMP_WARN_S:
            ms = seconds / 1000
            hint = (f"if it was meant in ms, write duration = {ms:g}"
                    if abs(ms * rate - round(ms * rate)) < 1e-6 and round(ms * rate) >= 1
                    else "durations are in s")
            ramp = "take-off" if phase.kind == "takeoff" else "landing"
            out.append(src.note(
                ("phase", i, "duration"),
                f"a {ramp} ramp of {seconds:g} s ({seconds / 60:.1f} min) is far longer than "
                f"usual (the shipped plans ramp 2-3 s; warned above {RAMP_WARN_S:g} s); "
                f"{hint}"))
        for e in phase.excitation:
            if e.axis not in _LIMIT:
                continue
            # A deg (deg/s) amplitude meant in rad (rad/s) and within the limit reads as at
            # most the limit in radians: below it, a unit slip is likely, and the excitation
            # is under 1/57 of what the vehicle allows, little to identify a model from
            # (the thesis flew 83 % of the roll/pitch limit and 25 % of the yaw-rate one).
            limit = getattr(plan.vehicle, _LIMIT[e.axis])
            floor = math.radians(limit)
            if abs(e.amplitude) < floor:
                unit = "deg" if e.axis != "yaw_rate" else "deg/s"
                rad = "rad" if e.axis != "yaw_rate" else "rad/s"
                sign = "" if e.signal == "step" else "±"  # a step goes one way
                out.append(src.note(
                    ("phase", i, e.axis, "amplitude"),
                    f"{sign}{abs(e.amplitude):g} {unit} is below {floor:.3g} {unit}, "
                    f"vehicle.{_LIMIT[e.axis]} = {limit:g} {unit} taken as {rad}: what an "
                    f"amplitude meant in {rad} looks like ({abs(e.amplitude):g} {rad} = "
                    f"{math.degrees(abs(e.amplitude)):.3g} {unit}), and too small to excite "
                    f"much; amplitudes are in {unit}"))
    return out
