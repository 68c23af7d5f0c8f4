"""Run the benchmarks: ``python -m bench [NAME ...]`` (NAME is bench_NAME.py, default: all)."""

from __future__ import annotations

import importlib
import pkgutil
import sys
import time

import bench


def main(argv: list[str]) -> int:
    available = sorted(
        m.name.removeprefix("bench_")
        for m in pkgutil.iter_modules(bench.__path__)
        if m.name.startswith("bench_")
    )
    wanted = argv or available
    unknown = [w for w in wanted if w not in available]
    if unknown:
        print(f"error: unknown benchmark(s) {unknown}; available: {available}", file=sys.stderr)
        return 2
    status = 0
    for name in wanted:
        print(f"=== bench {name}", flush=True)
        t0 = time.perf_counter()
        rc = importlib.import_module(f"bench.bench_{name}").main()
        verdict = "ok" if rc == 0 else "FAILED"
        print(f"=== bench {name}: {verdict} in {time.perf_counter() - t0:.1f} s")
        status |= rc
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
