"""Fuzz harness: mutated inputs into the tools that read what others made.

The targets (session reader, UDP simulator, importers, model files, flight plans) are
:mod:`tests.fuzz.targets`, one function each in its :data:`~tests.fuzz.targets.TARGETS`; what
damages or crafts their inputs is :mod:`tests.fuzz.mutators`. This module runs them:
:func:`supervise` runs a target's cases in a child process (``python -m tests.fuzz.harness
--child``) that prints one JSON line per case, and gives each case ``timeout_s`` of wall time:
a case that takes longer is a hang (the child is killed; the case's seed and index replay it).
HDF5 holds a global lock, so a hang cannot be timed out inside one process.

    python -m tests.fuzz.harness --target session --cases 2000 --seed 7
    make fuzz          # every target (session, udp, importers, model, plan), FUZZ_CASES each
"""

from __future__ import annotations

import argparse
import datetime
import json
import logging
import os
import random
import select
import signal
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

from tests.fuzz.targets import TARGETS


def date_seed() -> int:
    """Today's seed (UTC date as YYYYMMDD): varies by day, replayable from the printed value."""
    return int(datetime.datetime.now(datetime.UTC).strftime("%Y%m%d"))


def _child(target: str, seed: int, cases: int) -> None:
    """Run ``cases`` cases, one JSON line each on stdout (outcome or failure, seconds)."""
    logging.basicConfig(level=logging.CRITICAL)
    fn = TARGETS[target]
    with tempfile.TemporaryDirectory(prefix=f"fuzz-{target}-") as tmp:
        work = Path(tmp)
        for i in range(cases):
            rng = random.Random(f"{seed}-{target}-{i}")
            t0 = time.perf_counter()
            print(json.dumps({"case": i, "start": True}), flush=True)
            try:
                outcome, detail = fn(rng, work), ""
            except Exception as exc:
                outcome = "failure"
                detail = "".join(traceback.format_exception(exc))[-3000:]
            print(json.dumps({"case": i, "outcome": outcome, "detail": detail,
                              "seconds": time.perf_counter() - t0}), flush=True)


def supervise(*, target: str, seed: int, cases: int, timeout_s: float = 10.0) -> dict:
    """Run a target's cases in a child process; returns counts per outcome, failures (with
    their tracebacks; a child that dies mid-run, e.g. a segfault in a C reader, is one),
    hangs (cases past ``timeout_s``) and the slowest case's seconds."""
    cmd = [sys.executable, "-m", "tests.fuzz.harness", "--child", "--target", target,
           "--seed", str(seed), "--cases", str(cases)]
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root)}
    with tempfile.TemporaryFile(mode="w+") as errors:  # a crash's last words
        proc = subprocess.Popen([cmd[0], "-X", "faulthandler", *cmd[1:]], stdout=subprocess.PIPE,
                                stderr=errors, cwd=root, env=env, text=True, bufsize=1)
        report: dict = {"target": target, "seed": seed, "cases": 0, "outcomes": {},
                        "failures": [], "hangs": [], "slowest_s": 0.0}
        current, deadline = None, time.monotonic() + 120.0  # the first case builds the inputs
        try:
            while True:
                wait = max(0.0, deadline - time.monotonic())
                ready, _, _ = select.select([proc.stdout], [], [], wait)
                if not ready:
                    report["hangs"].append(current)
                    break
                line = proc.stdout.readline()
                if not line:  # the child is gone: done, or killed by what a case did
                    code = proc.wait()
                    if code or report["cases"] < cases:
                        report["failures"].append((current, _death(code, errors)))
                    break
                msg = json.loads(line)
                if msg.get("start"):
                    current = msg["case"]
                    if current > 0:
                        deadline = time.monotonic() + timeout_s
                    continue
                report["cases"] += 1
                report["outcomes"][msg["outcome"]] = report["outcomes"].get(msg["outcome"], 0) + 1
                report["slowest_s"] = max(report["slowest_s"], msg["seconds"])
                if msg["outcome"] == "failure":
                    report["failures"].append((msg["case"], msg["detail"]))
                deadline = time.monotonic() + timeout_s
        finally:
            proc.kill()
            proc.wait()
    return report


def _death(code: int, errors: object) -> str:
    """Why the child ended early or badly: its signal or exit code and the end of its
    stderr (faulthandler's stack of the crash)."""
    try:
        why = f"signal {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
    except ValueError:
        why = f"signal {-code}"
    errors.seek(0)
    stack = errors.read().split("\nExtension modules:")[0]  # faulthandler's, without the list
    return f"the process died ({why}): a crash in native code\n{stack[-2000:]}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m tests.fuzz.harness", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--target", choices=[*TARGETS, "all"], default="all")
    ap.add_argument("--seed", type=int, default=None, help="default: today's date, YYYYMMDD")
    ap.add_argument("--cases", type=int, default=2000)
    ap.add_argument("--timeout", type=float, default=10.0, help="seconds per case")
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    seed = date_seed() if args.seed is None else args.seed
    if args.child:
        _child(args.target, seed, args.cases)
        return 0
    bad = 0
    for target in TARGETS if args.target == "all" else [args.target]:
        r = supervise(target=target, seed=seed, cases=args.cases, timeout_s=args.timeout)
        print(f"{target}: seed {seed}, {r['cases']} cases, outcomes {r['outcomes']}, "
              f"{len(r['failures'])} failures, {len(r['hangs'])} hangs, slowest "
              f"{r['slowest_s']:.2f} s")
        for case, detail in r["failures"][:5]:
            print(f"  case {case}:\n{detail}")
        for case in r["hangs"]:
            print(f"  case {case}: no answer within {args.timeout:g} s (hang)")
        bad += len(r["failures"]) + len(r["hangs"])
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
