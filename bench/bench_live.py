"""Cost of the Rerun flight view per row: in the runner's thread (rows()) and in total.

Baseline measured in the same run: SessionWriter.append of the same rows (what the runner
does for every row anyway). Rows are fed one per call as fast as possible, so the runner's
figure includes waiting for the GIL while the view's worker converts and sends. Targets:
rows() alone (worker paused) <= 5x the session append; the whole view (all threads) under 1 %
of one core at flight rates; replay >= 200k rows/s.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from cfsession import SessionWriter, open_session
from groundstation.commands.replay import replay_session
from groundstation.live import open_view
from tests.viz.sessions import flight_specs

_SECONDS = 60


def _rows():
    """(stream, row) in flight order: 4 log blocks + setpoints at 100 Hz, link at 10 Hz."""
    out = []
    for k in range(_SECONDS * 100):
        t, fw = k * 0.01, (k * 10) % (1 << 24)
        out += [("motors", (t, fw, 30000, 31000, 32000, 33000)), ("acc", (t, fw, 0.0, 0.1, 1.0)),
                ("gyro", (t, fw, 1.0, 2.0, 3.0)), ("setpoints", (t, 1.0, 2.0, 3.0, 30000, 1, k))]
        if k % 2 == 0:
            out.append(("attitude", (t, fw, 0.5, 0.6)))
        if k % 10 == 0:
            out.append(("link", (t, 90.0, 5.0)))
    return out


def main() -> int:
    rows = _rows()
    with tempfile.TemporaryDirectory() as tmp:
        w = SessionWriter(Path(tmp) / "s.h5", streams=flight_specs(), flush_interval=1e9,
                          compress_on_close=False)
        t0 = time.perf_counter()
        for name, row in rows:
            w.append(name, row)
        base = time.perf_counter() - t0
        w.close()
        view = open_view(mode="save", name="bench", rrd_path=Path(tmp) / "v.rrd")
        view.begin(streams=flight_specs(), metadata={})
        t0 = time.process_time()
        w0 = time.perf_counter()
        caller = 0.0
        for name, row in rows:
            c0 = time.perf_counter()
            view.rows(name, [row])
            caller += time.perf_counter() - c0
        view.end(summary={})
        total_cpu = time.process_time() - t0
        wall = time.perf_counter() - w0
        quiet = open_view(mode="save", name="quiet", rrd_path=Path(tmp) / "q.rrd")
        quiet.background = False
        quiet.begin(streams=flight_specs(), metadata={})
        c0 = time.perf_counter()
        for name, row in rows:
            quiet.rows(name, [row])
        alone = time.perf_counter() - c0
        quiet.end(summary={})
        t0 = time.perf_counter()
        session = open_session(Path(tmp) / "s.h5")
        v2 = open_view(mode="save", name="replay", rrd_path=Path(tmp) / "r.rrd")
        n = sum(replay_session(session=session, view=v2).values())
        replay = time.perf_counter() - t0
    per = 1e6 / len(rows)
    print(f"{len(rows)} rows ({_SECONDS} s of flight)")
    print(f"session append (baseline): {base * per:6.2f} us/row")
    print(f"view rows() alone (worker paused): {alone * per:6.2f} us/row = "
          f"{alone / base:.2f}x baseline (target <= 5x)")
    print(f"view rows() with the worker running: {caller * per:6.2f} us/row = "
          f"{caller / base:.2f}x baseline")
    print(f"view total CPU (all threads, incl. rerun's): {total_cpu * per:6.2f} us/row = "
          f"{total_cpu / base:.2f}x baseline; {100 * total_cpu / _SECONDS:.2f} % of one core "
          f"in flight (wall {wall:.2f} s)")
    print(f"replay: {n} rows in {replay:.3f} s = {n / replay / 1e3:.0f}k rows/s (target >= 200k)")
    ok = alone <= 5 * base and total_cpu / _SECONDS < 0.01 and n / replay >= 200e3
    return 0 if ok else 1
