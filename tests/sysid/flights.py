"""Session files of a KNOWN linear system, logged like a real flight, for the bridge/CLI tests.

The system's samples ``u[k]``, ``y[k]`` belong to firmware instants ``k * 20 ms``. Three log
blocks (motors, acc, gyro) carry them with their own offsets (0, 3, 6 ms) plus 0-3 ms jitter,
a few dropped packets, a firmware tick that wraps (24 bits) mid-flight, and host receive times
``fw + host_offset + latency`` (2-6 ms). Phases: takeoff, excitation, landing on the host clock.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cfsession.schema import log_block_spec
from cfsession.writer import SessionWriter, standard_streams
from sysid.model import StateSpaceModel
from tests.sysid.systems import closed_loop, random_stable_system

__all__ = ["FW0_MS", "HOST_OFFSET", "PWM_GAIN", "PWM_MID", "Flight", "held", "known_system",
           "write_flight"]

DT = 0.02
PWM_MID, PWM_GAIN = 40000.0, 2000.0
FW0_MS = (1 << 24) - 20_000  # the 24-bit tick wraps 20 s into the flight
HOST_OFFSET = 0.5  # host time of firmware tick FW0 (s), before latency
OFFSETS_MS = {"motors": 0, "acc": 3, "gyro": 6}
EXCITATION = (5.0, 45.0)  # nominal host-time phase boundaries (s)


@dataclass(frozen=True)
class Flight:
    """What was written: the stored values per stream (n, c), the truth model in PWM units,
    dropped sample indices per stream and the phases' host times."""

    path: Path
    values: dict[str, np.ndarray]
    dropped: dict[str, np.ndarray]
    system: StateSpaceModel
    excitation: tuple[float, float]
    y_clean: np.ndarray


def known_system(seed: int = 6) -> StateSpaceModel:
    """4 states, 4 inputs (motors), 6 outputs (acc, gyro), 50 Hz; stable in the loop (0.77)."""
    return random_stable_system(n_states=4, n_inputs=4, n_outputs=6,
                                rng=np.random.default_rng(seed), radius=(0.6, 0.95))


def write_flight(path: Path, *, system: StateSpaceModel, seed: int, n: int = 2500,
                 n_drop: int = 5, noise_std: float = 0.05,
                 phases: list[tuple[float, str, str]] | None = None,
                 metadata: dict[str, object] | None = None,
                 pwm_extra: np.ndarray | None = None) -> Flight:
    """Simulate ``system`` in closed loop for ``n`` samples and write it as a session.

    ``phases`` ``(host time, name, kind)`` replace takeoff/excitation/landing (e.g. the
    ``ground-0``/``airborne-1``/... of an imported log); ``metadata`` adds root attributes
    (``uri``, ``plan_name``, ...) to the default ``uri``; ``pwm_extra`` (n, 4) is added to the
    logged motor commands only (what the log saw but the vehicle did not feel)."""
    rng = np.random.default_rng(seed)
    exp = closed_loop(system, n_samples=n, rng=rng, gain=0.25, noise_std=noise_std)
    pwm = np.round(PWM_MID + PWM_GAIN * exp.data.u + (0 if pwm_extra is None else pwm_extra))
    values = {"motors": pwm, "acc": exp.data.y[:, :3].astype(np.float32).astype(float),
              "gyro": exp.data.y[:, 3:].astype(np.float32).astype(float)}
    specs = [
        log_block_spec(name="motors", variables=[(f"motor.m{i}", "uint16_t") for i in range(1, 5)],
                       period_s=DT),
        log_block_spec(name="acc", variables=[(f"acc.{a}", "float") for a in "xyz"], period_s=DT),
        log_block_spec(name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"],
                       period_s=DT),
    ]
    dropped = {}
    with SessionWriter(path, streams=[*specs, *standard_streams()],
                       metadata={"uri": "test://known", **(metadata or {})}) as w:
        t_end = HOST_OFFSET + n * DT
        table = phases or [(0.0, "takeoff", "takeoff"), (EXCITATION[0], "excitation",
                                                          "excitation"),
                           (EXCITATION[1], "landing", "landing")]
        for pid, (t, name, kind) in enumerate(table):
            w.phase(t=t, phase_id=pid, name=name, kind=kind)
        for spec in specs:
            drop = np.sort(rng.choice(np.arange(10, n - 10), n_drop, replace=False))
            dropped[spec.name] = drop
            fw_ms = FW0_MS + 20 * np.arange(n) + OFFSETS_MS[spec.name] + rng.integers(0, 4, n)
            host = HOST_OFFSET + (fw_ms - FW0_MS) / 1000.0 + rng.uniform(0.002, 0.006, n)
            rows = [(float(host[k]), int(fw_ms[k]) % (1 << 24), *values[spec.name][k].tolist())
                    for k in range(n) if k not in set(drop.tolist())]
            w.extend(spec.name, rows)
        w.close(duration_s=t_end)
    truth = system.replace(B=system.B / PWM_GAIN, D=system.D / PWM_GAIN,
                           input_names=[f"motor.m{i}" for i in range(1, 5)],
                           output_names=[f"acc.{a}" for a in "xyz"] + [f"gyro.{a}" for a in "xyz"])
    return Flight(path=path, values=values, dropped=dropped, system=truth,
                  excitation=EXCITATION, y_clean=exp.y_clean)


def held(values: np.ndarray, dropped: np.ndarray, index: np.ndarray) -> np.ndarray:
    """``values[index]`` where a dropped sample is replaced by the last one received."""
    keep = np.ones(len(values), dtype=bool)
    keep[dropped] = False
    last = np.maximum.accumulate(np.where(keep, np.arange(len(values)), -1))
    return values[last[index]]
