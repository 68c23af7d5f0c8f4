"""The uSD-card log reader on flight-test-sized logs, time and peak memory: ``python -m bench usd``.

Two synthetic logs of about 40 MB (``tests/importers/usd_logs.py``), each declaring an event
that has no records as the firmware's do: 500 s of a 1 kHz ``fixedFrequency`` event (20
variables, 80-byte records: the deck's usual mode, one run of records of one size), and 400 s of
it interleaved with a second event of 7 floats at 270 Hz (records of two sizes, irregularly
interleaved: walked one by one). For each, :func:`groundstation.importers.read_usd` against the
baseline measured in the same run: the straightforward per-record parse the reader used to be
(:func:`tests.importers.usd_logs.reference_read`: ``struct`` per record, Python tuples, then
arrays), which must give the same arrays. Time is wall time (best of 3); peak memory is
``tracemalloc``'s (numpy's arrays included), in a run of its own. Targets: the reader at least
5x faster than the baseline and at most 3x the file's size at its peak (the file's bytes are
held while decoding); the baseline took about 15x.

Then ``groundstation import`` of the mixed log in a child process: its peak RSS above that of a
child that only imports the same modules (target: at most 6x the file's size; the session
writer takes rows as tuples, and compresses the file in memory at close).
"""

from __future__ import annotations

import gc
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

import numpy as np

from groundstation.importers import read_usd
from tests.importers.usd_logs import reference_read, same_values, synthetic_usd

__all__ = ["main"]

SPEEDUP = 5.0
PEAK_OVER_FILE = 3.0
IMPORT_OVER_FILE = 6.0
_CHILD = """import sys, tempfile
from pathlib import Path
from groundstation.importers import usd_to_session
if sys.argv[1] != "-":
    usd_to_session(source=sys.argv[1], out=Path(tempfile.mkdtemp(dir=sys.argv[2])) / "x.h5")
print(next(ln for ln in open("/proc/self/status") if ln.startswith("VmHWM")).split()[1])
"""


def _best_time(fn: Callable[[], object], repeat: int = 3) -> float:
    best = float("inf")
    for _ in range(repeat):
        gc.collect()
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _peak_bytes(fn: Callable[[], object]) -> int:
    gc.collect()
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def _same(path: Path) -> bool:
    """The reader's arrays equal the baseline's: values (NaNs quiet), dtypes and timestamps."""
    ref, log = reference_read(path.read_bytes()), read_usd(path)
    for name, (stamps, values) in ref.items():
        ev = log.events[name]
        scale = 1e-3 if log.version == 1 else 1e-6
        if not np.array_equal(ev.timestamps_s, stamps.astype(np.float64) * scale):
            return False
        if not all(same_values(ev.values[var], col) for var, col in values.items()):
            return False
    return True


def _child_rss_mb(args: list[str]) -> float:
    """Peak RSS of a child running :data:`_CHILD` with ``args``, MB (its own ``VmHWM``: the
    rusage of children counts the parent's pages a forked child starts with)."""
    run = subprocess.run([sys.executable, "-W", "ignore", "-c", _CHILD, *args], check=True,
                         capture_output=True, text=True)
    return int(run.stdout.split()[-1]) / 1024


def main() -> int:
    ok = True
    with tempfile.TemporaryDirectory(prefix="bench-usd-") as tmp:
        logs = {"fixedFrequency only": synthetic_usd(seconds=500, rate_hz=1000),
                "two events, mixed": synthetic_usd(seconds=400, rate_hz=1000, mixed=True)}
        for label, data in logs.items():
            path = Path(tmp) / label.replace(" ", "_").replace(",", "")
            path.write_bytes(data)
            mb = len(data) / 1e6
            del data
            same = _same(path)
            new_s = _best_time(lambda p=path: read_usd(p))
            old_s = _best_time(lambda p=path: reference_read(p.read_bytes()), repeat=1)
            new_peak = _peak_bytes(lambda p=path: read_usd(p)) / 1e6
            old_peak = _peak_bytes(lambda p=path: reference_read(p.read_bytes())) / 1e6
            print(f"{label}: {mb:.1f} MB log, arrays identical to the baseline's: {same}")
            print(f"  time: reader {new_s:.3f} s, baseline (per-record parse) {old_s:.2f} s; "
                  f"speed-up {old_s / new_s:.1f}x (target >= {SPEEDUP:.0f}x: "
                  f"{SPEEDUP / (old_s / new_s):.2f} of it)")
            print(f"  peak memory: reader {new_peak:.0f} MB = {new_peak / mb:.2f}x the file "
                  f"(target <= {PEAK_OVER_FILE:.0f}x: {new_peak / mb / PEAK_OVER_FILE:.2f} of "
                  f"it), baseline {old_peak:.0f} MB = {old_peak / mb:.1f}x; reader / baseline "
                  f"= {new_peak / old_peak:.2f}")
            ok &= same and old_s / new_s >= SPEEDUP and new_peak / mb <= PEAK_OVER_FILE
        idle = _child_rss_mb(["-"])
        full = _child_rss_mb([str(path), tmp])
        print(f"groundstation import of the mixed log, child process: peak RSS {full:.0f} MB, "
              f"{full - idle:.0f} MB above a child that only imports the modules ({idle:.0f} MB)"
              f" = {(full - idle) / mb:.2f}x the file (target <= {IMPORT_OVER_FILE:.0f}x: "
              f"{(full - idle) / mb / IMPORT_OVER_FILE:.2f} of it)")
        ok &= (full - idle) / mb <= IMPORT_OVER_FILE
    return 0 if ok else 1
