"""Live identification at thesis size (sysid.live): 4 inputs, 6 outputs, order 8, p 60, f 17,
N growing to 15 000 samples at 50 Hz. Each second 50 rows are appended (the incremental Gram,
O(50 (Bc)^2)) and one update runs (centring/scaling of the Gram, Cholesky, IEM realisation).
Target: one update (append + update) well under 1 s at N = 15 000. Also checks the final live
model against the offline ``sysid.iem`` of the same (mean-removed) samples.
"""

from __future__ import annotations

import time

import numpy as np

from sysid import detrend_data, iem
from sysid.live import LiveIdentifier
from tests.sysid.systems import closed_loop, random_stable_system

_N, _RATE, _M, _L, _ORDER, _P, _F = 15_000, 50, 4, 6, 8, 60, 17


def main() -> int:
    rng = np.random.default_rng(16)
    system = random_stable_system(n_states=_ORDER, n_inputs=_M, n_outputs=_L, rng=rng, dt=1 / _RATE)
    data = closed_loop(system, n_samples=_N, rng=rng, gain=0.1).data
    live = LiveIdentifier(n_inputs=_M, n_outputs=_L, order=_ORDER, past=_P, future=_F,
                          dt=1 / _RATE)
    append_s, update_s = [], []
    last = None
    for stop in range(_RATE, _N + 1, _RATE):
        start = live.n_samples
        t0 = time.perf_counter()
        live.append(u=data.u[start:stop], y=data.y[start:stop])
        t1 = time.perf_counter()
        append_s.append(t1 - t0)
        if (live.n_samples >= live.min_samples and stop % (10 * _RATE) == 0) or stop == _N:
            last = live.update()
            update_s.append(time.perf_counter() - t1)
    assert last is not None
    t0 = time.perf_counter()
    ref = iem(detrend_data(data, kind="mean")[0], order=_ORDER, past=_P, future=_F)
    offline_s = time.perf_counter() - t0
    sort = lambda p: p[np.lexsort((p.imag, p.real))]  # noqa: E731
    diff = float(np.max(np.abs(sort(last.poles) - sort(ref.poles()))))
    total = append_s[-1] + update_s[-1]
    print(f"append of {_RATE} rows: median {np.median(append_s) * 1e3:.1f} ms, "
          f"max {max(append_s) * 1e3:.1f} ms")
    print(f"update at N={_N}: {update_s[-1] * 1e3:.0f} ms (append + update {total * 1e3:.0f} ms;"
          f" offline sysid.iem from scratch {offline_s * 1e3:.0f} ms)")
    print(f"max |pole live - pole offline| = {diff:.2e}")
    ok = total < 0.5 and diff < 1e-6
    print("target: append + update < 0.5 s, poles equal to 1e-6:", "met" if ok else "MISSED")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
