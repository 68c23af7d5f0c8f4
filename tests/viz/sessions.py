"""Synthetic flight sessions for the viz tests (written with SessionWriter, no flight)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from cfsession.schema import StreamSpec, live_id_spec, log_block_spec
from cfsession.writer import SessionWriter, standard_streams

__all__ = ["LONG_TEXT", "N_LOG", "flight_rows", "flight_specs", "live_id_rows", "write_session"]

N_LOG = 500
FW_START_MS = (1 << 24) - 1234  # the 24-bit firmware tick wraps 1.234 s into the flight
LONG_TEXT = "battery sag during excitation: " + "é" * 150 + " end"  # > 200 bytes: 2 rows


def flight_specs() -> list[StreamSpec]:
    motors = log_block_spec(name="motors", variables=[(f"motor.m{i}", "uint16_t")
                                                      for i in range(1, 5)], period_s=0.01)
    acc = log_block_spec(name="acc", variables=[("acc.x", "float"), ("acc.y", "float"),
                                                ("acc.z", "float")], period_s=0.01)
    gyro = log_block_spec(name="gyro", variables=[("gyro.x", "float"), ("gyro.y", "float"),
                                                  ("gyro.z", "float")], period_s=0.01)
    att = log_block_spec(name="attitude", variables=[("stabilizer.roll", "float"),
                                                     ("stabilizer.pitch", "float")],
                         period_s=0.02)
    return [motors, acc, gyro, att, *standard_streams()]


def flight_rows() -> dict[str, list[tuple]]:
    """Rows per stream in field order (host_time first), as the flight runner hands them over.

    Log rows arrive 3 ms after their firmware tick; link samples alternate quality-only and
    latency-only (NaN in the other); events include a long text continued on a second row.
    """
    k = np.arange(N_LOG)
    t = 0.003 + 0.01 * k
    fw = (FW_START_MS + 10 * k) % (1 << 24)
    rows: dict[str, list[tuple]] = {}
    rows["motors"] = [(t[i], int(fw[i]), 30000 + i, 31000 + i, 32000 - i, 33000 - i)
                      for i in k]
    rows["acc"] = [(t[i], int(fw[i]), 0.01 * i, -0.01 * i, 1.0) for i in k]
    rows["gyro"] = [(t[i], int(fw[i]), np.sin(0.1 * i), np.cos(0.1 * i), 0.5 * i) for i in k]
    rows["attitude"] = [(t[i], int(fw[i]), 0.1 * i, -0.1 * i) for i in k[::2]]
    rows["setpoints"] = [(0.01 * i, (i % 7) - 3.0, 2.0 - (i % 5), 10.0 * ((i // 50) % 2),
                          30000 + 10 * i, i // 200, i) for i in range(400)]
    rows["link"] = [(0.1 * i, 95.0 - i if i % 2 == 0 else np.nan,
                     np.nan if i % 2 == 0 else 4.0 + i) for i in range(50)]
    rows["phases"] = [(0.0, 0, b"takeoff", b"takeoff"), (2.0, 1, b"prbs", b"excitation"),
                      (4.0, 2, b"land", b"landing")]
    data = LONG_TEXT.encode()
    rows["events"] = [(0.5, 2, b"runner", b"armed", 0),
                      (1.5, 3, b"safety", data[:200], 0), (1.5, 3, b"safety", data[200:], 1),
                      (4.9, 4, b"link", b"link lost", 0)]
    return rows


def live_id_rows(n: int, *, order: int = 4) -> np.ndarray:
    """``n`` rows of a ``live_id`` stream with ``order`` pole columns, one update every 0.5 s.

    The orders vary: some rows have fewer poles than columns, one none, one more than the file
    stores (capped); pole_move is NaN at the first update, fit_pct NaN at every 7th.
    """
    data = np.zeros(n, dtype=live_id_spec(order=order).dtype)
    k = np.arange(n)
    data["host_time"] = 1.0 + 0.5 * k
    data["order"] = np.where(k % 5 == 3, order - 1, order)
    data["order"][k == 2] = 0
    data["order"][k == 4] = order + 3
    data["fit_pct"] = np.where(k % 7 == 6, np.nan, 50.0 + 40.0 * (1 - np.exp(-0.01 * k)))
    data["innovation_nvar"] = 0.5 * np.exp(-0.01 * k)
    data["pole_move"] = np.where(k == 0, np.nan, 0.1 / (1 + k))
    data["max_pole"] = 0.99 - 0.001 * (k % 10)
    data["final"][-1:] = 1
    for i in range(1, order + 1):
        data[f"pole_re_{i}"] = 0.9 - 0.05 * i + 1e-4 * k
        data[f"pole_im_{i}"] = (-1) ** i * 0.01 * i
    return data


def write_session(path: Path, *, live_id: int = 0, rename: dict[str, str] | None = None) -> Path:
    """A closed session file holding :func:`flight_rows`, with ``live_id`` that many
    :func:`live_id_rows`; ``rename`` names streams otherwise (a file made elsewhere)."""
    specs = flight_specs() + ([live_id_spec(order=4)] if live_id else [])
    new = dict(rename or {})
    with SessionWriter(path, streams=[replace(s, name=new.get(s.name, s.name)) for s in specs],
                       metadata={"plan_name": "prbs-test", "uri": "sim://0"}) as w:
        for name, rows in flight_rows().items():
            w.extend(new.get(name, name), rows)
        if live_id:
            w.extend(new.get("live_id", "live_id"), live_id_rows(live_id).tolist())
    return path
