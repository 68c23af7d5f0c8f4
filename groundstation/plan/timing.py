"""PRBS clock period and register length from a model's modes (Rivera and Jun 2000, "An
integrated identification and control design methodology for multivariable process system
applications"); the rule and its figures are in ``docs/flightplans.md`` ("Designing the next
flight"), the caller that decides when a model is trusted to lengthen the chip is
:func:`groundstation.plan.design.design_plan`.

With :math:`s = \\ln z / dt` per pole, the modes at or below the setpoints' Nyquist frequency
count: :math:`\\tau_L = 1 / \\max |s|` (the fastest) and
:math:`\\tau_H = \\max 1 / |\\mathrm{Re}\\,s|` over those that settle within the phase (the
slowest); then

* chip :math:`T_{sw} = P / f_s \\le 2.78\\,\\tau_L / \\alpha_s`, in whole setpoint ticks P;
* period :math:`N T_{sw} \\ge 2\\pi \\beta_s \\tau_H` with :math:`N = 2^n - 1`, at most the phase.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from groundstation.errors import PlanError
from groundstation.plan.excitation import LFSR_TAPS

__all__ = ["ALPHA_S", "BETA_S", "SWITCH", "Timing", "prbs_timing"]

SWITCH, ALPHA_S, BETA_S = 2.78, 2.0, 3.0
"""PRBS power is down by half at 2.78 / T_sw rad/s; closed loop alpha_s times faster than the
open loop; beta_s time constants to settle (Rivera and Jun 2000)."""


class Timing(NamedTuple):
    """A PRBS's chip (setpoint ticks) and register length, why each, and whether the chip was
    capped below what the model's modes allow."""

    clock: int
    register_length: int
    why_clock: str
    why_register: str
    capped: bool = False


def prbs_timing(*, poles: np.ndarray, dt: float, rate_hz: float, n_ticks: int,
                horizon_ticks: float = 0.0, max_clock: int | None = None,
                min_period_ticks: int = 0, untrusted: str = "") -> Timing | None:
    """The chip and register from the model's modes (module docstring); None when no mode
    below the setpoints' Nyquist frequency settles within the phase. ``max_clock`` (ticks)
    caps the chip and ``min_period_ticks`` floors the period, with ``untrusted`` saying why:
    the flown chip and period, when the model is not trusted to lengthen the one or shorten
    the other (:func:`groundstation.plan.design.design_plan`: a model that explains the
    flight poorly may miss the fast modes and the slow ones alike; a 16 % fit cut a 10-bit
    PRBS to 3 bits); the period is then chosen for the capped chip."""
    z = np.asarray(poles, dtype=complex)
    z = z[(np.abs(z) > 1e-12) & (np.abs(z) < 1.0)]
    s = np.log(z) / dt  # continuous-time equivalents, rad/s
    speed, decay = np.abs(s), -1.0 / s.real  # natural frequency; decay time constant, s
    tick, phase_s = 1.0 / rate_hz, n_ticks / rate_hz
    band = speed <= math.pi * rate_hz  # at or below the setpoints' Nyquist frequency
    settles = band & (decay <= phase_s)  # slower modes act as integrators over the phase
    if not settles.any():
        return None
    tau_l, tau_h = float(1.0 / speed[band].max()), float(decay[settles].max())
    clock = max(1, math.floor(SWITCH * tau_l / ALPHA_S / tick + 1e-9))
    why_clock = (f"chip {clock * tick:g} s <= 2.78 tau_L / alpha_s = 2.78 x {tau_l:.3g} s / "
                 f"{ALPHA_S:g} = {SWITCH * tau_l / ALPHA_S:.3g} s (fastest mode below the "
                 f"setpoint Nyquist)" + (", at least one tick" if clock == 1 else ""))
    capped = max_clock is not None and clock > max_clock
    if capped:
        why_clock = (f"chip {max_clock * tick:g} s as flown: the model's fastest mode below the "
                     f"setpoint Nyquist (tau_L = {tau_l:.3g} s) would allow "
                     f"{clock * tick:g} s, but {untrusted}")
        clock = int(max_clock)
    want = 2 * math.pi * BETA_S * tau_h
    asked = max(want / tick, horizon_ticks)  # ticks of period the model and horizons ask for

    def registers(chip: int) -> list[int]:
        return [n for n in LFSR_TAPS if ((1 << n) - 1) * chip <= n_ticks]

    if min_period_ticks and max_clock is not None and clock < max_clock and not any(
            ((1 << n) - 1) * clock >= min_period_ticks for n in registers(clock)):
        why_clock = (f"chip {max_clock * tick:g} s as flown: the model's "
                     f"{clock * tick:g} s chips hold no period as long as the flown "
                     f"{min_period_ticks * tick:g} s within the phase, and {untrusted}")
        clock = int(max_clock)  # the flown chip and period: they fitted the phase
    fits = registers(clock)
    if not fits:
        raise PlanError(f"an excitation phase of {phase_s:g} s cannot hold one period of a "
                        f"PRBS with {clock * tick:g} s chips; lengthen it to at least "
                        f"{3 * clock * tick:g} s")
    n = next((n for n in fits if ((1 << n) - 1) * clock >= min_period_ticks
              and ((1 << n) - 1) * clock >= asked * (1 - 1e-9)), fits[-1])
    period = ((1 << n) - 1) * clock  # ticks
    why_reg = (f"period {(1 << n) - 1} x {clock * tick:g} s = {period * tick:g} s vs 2 pi "
               f"beta_s tau_H = 2 pi x {BETA_S:g} x {tau_h:.3g} s = {want:.3g} s (slowest mode)")
    if min_period_ticks > asked * (1 + 1e-9) and period >= min_period_ticks:
        why_reg += f"; at least the flown {min_period_ticks * tick:g} s: {untrusted}"
    if period < asked * (1 - 1e-9):
        why_reg += (f"; capped by the {phase_s:g} s phase (lengthen it to "
                    f"{max(want, horizon_ticks * tick):.0f} s for all)")
    return Timing(clock, n, why_clock, why_reg, capped)
