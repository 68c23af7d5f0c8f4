"""Mutated cfclient CSVs and uSD logs for the importers, and one import judged.

Used by ``tests/importers/test_fuzz.py`` (a few hundred cases a run) and runnable for a bigger
campaign: ``.venv/bin/python -m tests.importers.fuzz --cases 5000 [--seed N]``.
"""

from __future__ import annotations

import argparse
import datetime
import random
import struct
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main as gs
from tests.importers.usd_logs import build_usd, with_crc

TOKENS = [b",", b"\n", b"nan", b"inf", b"1e309", b"-", b".", b"g.", b"a.x", b"b.x", b"a_x",
          b"g.host_time", b"fw_time_ms", b"\x00", "é".encode(), b"\xff\xfe", b"x" * 300, b"",
          b"Timestamp", b"-1", b"4294967296", b"16777215", b"0x10", b"1_0", b" ", b"\r\n"]


def date_seed() -> int:
    """Today's date as a number (UTC): the seed changes daily, and a failure names it."""
    return int(datetime.datetime.now(datetime.UTC).strftime("%Y%m%d"))


def valid_csv(rng: random.Random) -> bytes:
    n_vars = rng.randint(1, 6)
    names = [f"{rng.choice(['motor', 'gyro', 'stateEstimate', 'a', 'b'])}."
             f"{rng.choice(['x', 'm1', 'z', 'a_x', 'host_time'])}{i if rng.random() < 0.5 else ''}"
             for i in range(n_vars)]
    names = list(dict.fromkeys(names))
    lines = ["Timestamp," + ",".join(names)]
    t = rng.randint(0, 1 << 24)
    for _ in range(rng.randint(1, 40)):
        t = (t + 10) % (1 << 24)
        lines.append(",".join([str(t)] + [f"{rng.uniform(-1e5, 1e5):.3f}" for _ in names]))
    return ("\n".join(lines) + "\n").encode()


def valid_usd(rng: random.Random) -> bytes:
    version = rng.choice([1, 2])
    events = []
    for eid in range(1, rng.randint(1, 3) + 1):
        kinds = [rng.choice("BbHhIife") for _ in range(rng.randint(0, 6))]
        names = [f"{rng.choice(['motor', 'stateEstimate', 'a', 'b', 'g'])}."
                 f"{rng.choice(['x', 'z', 'm1', 'a_x', 'host_time'])}{j}"
                 for j in range(len(kinds))]
        events.append((eid, f"ev{eid}" if eid > 1 else "fixedFrequency", names, kinds))
    t = rng.randint(0, 10**6)
    records = []
    for _ in range(rng.randint(0, 60)):
        eid, _name, _names, kinds = rng.choice(events)
        t += rng.randint(0, 20_000)
        records.append((eid, t, bytes(rng.getrandbits(8)
                                      for _ in range(struct.calcsize("<" + "".join(kinds))))))
    return build_usd(version=version, records=records,
                     events=[(eid, name, list(zip(names, kinds, strict=True)))
                             for eid, name, names, kinds in events])


def mutate(data: bytes, rng: random.Random, *, usd: bool) -> bytes:
    """One to three byte-level mutations; for uSD logs, the CRC is made right again half the
    time so that the mutation reaches the header and record parsers."""
    b = bytearray(data[:-4] if usd else data)
    for _ in range(rng.randint(1, 3)):
        op = rng.randrange(7)
        i = rng.randrange(len(b) + 1)
        if op == 0 and b:  # flip a byte
            b[min(i, len(b) - 1)] ^= 1 << rng.randrange(8)
        elif op == 1:  # delete a range
            del b[i:i + rng.randint(1, 16)]
        elif op == 2:  # duplicate a range
            b[i:i] = b[i:i + rng.randint(1, 64)]
        elif op == 3:  # insert a token
            b[i:i] = rng.choice(TOKENS)
        elif op == 4:  # truncate
            del b[i:]
        elif op == 5 and not usd:  # a header that name-mangling must survive, or too wide
            width = rng.choice([2, 3, 600, 5000])
            names = [rng.choice(["a.x", "b.x", "a_x", "g.host_time", "g.", "x", "a.b.c"])
                     + (str(k) if rng.random() < 0.5 else "") for k in range(width)]
            rest = bytes(b).split(b"\n", 1)
            b = bytearray(b"Timestamp," + ",".join(names).encode() + b"\n"
                          + (rest[1] if len(rest) > 1 else b""))
        elif op == 6 and usd and len(b) > 8:  # a random 16-bit count in the header
            j = rng.randrange(1, min(len(b) - 1, 64))
            b[j:j + 2] = struct.pack("<H", rng.choice([0, 1, 2, 513, 65535, rng.getrandbits(16)]))
    if not usd:
        return bytes(b)
    return with_crc(bytes(b)) if rng.random() < 0.5 else bytes(b) + data[-4:]


@dataclass(frozen=True)
class Outcome:
    ok: bool
    problem: str  # '' when the outcome is acceptable
    seconds: float


def judge_one(src: Path, out: Path, *, allow_damaged: bool) -> Outcome:
    """Import ``src``: a readable, cleanly closed session (exit 0) or one error line (exit 2)."""
    args = ["import", str(src), "--out", str(out)] + (["--allow-damaged"] if allow_damaged else [])
    t0 = time.perf_counter()
    res = CliRunner().invoke(gs, args)
    seconds = time.perf_counter() - t0
    if res.exit_code == 0:
        try:
            sessions = [open_session(p) for p in out.glob("*.h5")]
        except Exception as exc:  # any failure to read back is the finding
            return Outcome(True, f"imported but unreadable: {exc!r}", seconds)
        if len(sessions) != 1 or not sessions[0].closed_cleanly:
            return Outcome(True, f"exit 0 but {len(sessions)} session(s) written", seconds)
        return Outcome(True, "", seconds)
    err = res.stderr
    if res.exit_code != 2 or not err.startswith("error: ") or err.count("\n") != 1:
        return Outcome(False, f"exit {res.exit_code}, {res.exception!r}: {err[-300:]!r}",
                       seconds)
    leftovers = list(out.iterdir()) if out.exists() else []
    if leftovers:
        return Outcome(False, f"failed import left {[p.name for p in leftovers]}", seconds)
    return Outcome(False, "", seconds)


def case(seed: int, index: int, folder: Path) -> tuple[Path, Outcome]:
    """Build mutated input number ``index`` of ``seed`` under ``folder`` and judge its import."""
    rng = random.Random(f"{seed}-{index}")
    usd = index % 2 == 1
    data = mutate(valid_usd(rng) if usd else valid_csv(rng), rng, usd=usd)
    src = folder / (f"log{index:05d}" if usd else f"Blk{index:05d}-20240101T10-00-00.csv")
    src.write_bytes(data)
    return src, judge_one(src, folder / f"out{index:05d}", allow_damaged=rng.random() < 0.5)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cases", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=date_seed())
    args = ap.parse_args(argv)
    bad, imported, slowest = [], 0, 0.0
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.cases):
            _src, outcome = case(args.seed, i, Path(tmp))
            imported += outcome.ok and not outcome.problem
            slowest = max(slowest, outcome.seconds)
            if outcome.problem:
                bad.append(f"case {i}: {outcome.problem}")
    print(f"seed {args.seed}: {args.cases} cases, {imported} imported, "
          f"{args.cases - imported - len(bad)} refused in one line, {len(bad)} problems, "
          f"slowest {slowest:.2f} s")
    for line in bad[:20]:
        print(line)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
