"""Fuzz harness: mutated inputs into the tools that read what others made.

One function per target, registered in :data:`TARGETS`: ``target(rng, work) -> outcome`` makes
one case (a mutated input, from ``rng`` only, so a seed replays a run), feeds it to the code
under test and returns a short outcome label (``"ok"``, ``"flagged"``, ``"refused"``, ...). A
user error must be one line (:func:`one_line`); anything else that escapes is a failure.

:func:`supervise` runs the cases in a child process (``python -m tests.fuzz.harness --child``)
that prints one JSON line per case, and gives each case ``timeout_s`` of wall time: a case
that takes longer is a hang (the child is killed; the case's seed and index replay it). HDF5
holds a global lock, so a hang cannot be timed out inside one process.

Add a target: write ``def my_target(rng, work) -> str`` and add it to :data:`TARGETS`.

    python -m tests.fuzz.harness --target session --cases 2000 --seed 7
    make fuzz          # every target (session, udp, importers, model), FUZZ_CASES each
"""

from __future__ import annotations

import argparse
import datetime
import functools
import json
import logging
import os
import random
import select
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path

Target = Callable[[random.Random, Path], str]


def date_seed() -> int:
    """Today's seed (UTC date as YYYYMMDD): varies by day, replayable from the printed value."""
    return int(datetime.datetime.now(datetime.UTC).strftime("%Y%m%d"))


def one_line(exc: BaseException) -> str:
    """The message of a user error, checked to be one short line (AssertionError otherwise)."""
    msg = str(exc)
    assert msg and "\n" not in msg and len(msg) < 1000 and "Traceback" not in msg, repr(msg)
    return msg


# ------------------------------------------------------------------------- session reader


@functools.cache
def _session_bases(work: Path) -> tuple[bytes, ...]:
    """A cleanly closed (compressed) session and one left by a writer that died."""
    from cfsession.schema import log_block_spec
    from cfsession.writer import SessionWriter, standard_streams

    def write(path: Path) -> SessionWriter:
        blocks = [log_block_spec(name=n, variables=[(f"{n}.x", "float"), (f"{n}.y", "float"),
                                                    (f"{n}.z", "float")], period_s=0.02)
                  for n in ("gyro", "acc")]
        w = SessionWriter(path, streams=[*blocks, *standard_streams()],
                          metadata={"uri": "sim://0", "plan_name": "fuzz",
                                    "phase_table": [{"name": "hover"}]})
        w.phase(t=0.0, phase_id=0, name="hover", kind="hover")
        for k in range(400):
            w.append("gyro", (k * 0.02, (20 * k + 7) % (1 << 24), 1.0, float(k % 9), -2.0))
            if k % 7:  # a few dropped packets
                w.append("acc", (k * 0.02, (20 * k + 7) % (1 << 24), 0.0, 0.0, 1.0))
            if k % 5 == 0:
                w.append("setpoints", (k * 0.02, float(k % 3), 0.0, 0.0, 39000, 0, k // 5))
            if k % 100 == 0:
                w.event(t=k * 0.02, text=f"event {k} " + "x" * (k // 2))
                w.flush()
        w.flush(fsync=True)
        return w

    crashed = work / "base-crashed.h5"
    w = write(crashed)
    data = crashed.read_bytes()  # what a kill at this instant leaves
    w.close()
    clean = work / "base-clean.h5"
    write(clean).close(summary={"ok": 1})
    return clean.read_bytes(), data


def _mutate(rng: random.Random, data: bytes) -> bytes:
    b = bytearray(data)
    how = rng.random()
    if how < 0.5:  # a few flipped bytes, anywhere
        for _ in range(rng.choice([1, 1, 2, 4, 16])):
            i = rng.randrange(len(b))
            b[i] ^= 1 << rng.randrange(8) if rng.random() < 0.5 else rng.randrange(1, 256)
    elif how < 0.7:  # a range overwritten
        i = rng.randrange(len(b))
        n = rng.randrange(1, 64)
        b[i:i + n] = rng.choice([bytes(n), b"\xff" * n, rng.randbytes(n)])
    elif how < 0.85:  # truncated
        del b[rng.randrange(len(b)):]
    else:  # a metadata byte: in the first 4 kB most objects' headers live
        i = rng.randrange(min(4096, len(b)))
        b[i] = rng.randrange(256)
    return bytes(b)


def _crafted(rng: random.Random, work: Path, path: Path, clean: bytes) -> None:
    """A structurally valid file crafted to read elsewhere, exhaust memory or confuse types."""
    import h5py
    import numpy as np

    path.write_bytes(clean)
    how = rng.randrange(9)
    with h5py.File(path, "a") as f:
        if how == 0:  # external storage: another file's bytes as data
            secret = work / "secret.bin"
            secret.write_bytes(b"root:x:0:0:root:/root:/bin/bash\n" * 8)
            del f["gyro/data"]
            f["gyro"].create_dataset("data", shape=(4,), dtype=f["acc/data"].dtype,
                                     external=[(str(secret), 0, h5py.h5f.UNLIMITED)])
        elif how == 1:
            f["stolen"] = h5py.ExternalLink(str(work / "base-clean.h5"), "/gyro")
        elif how == 2:
            f["loop"] = h5py.SoftLink("/loop")
        elif how == 3:  # a virtual dataset
            layout = h5py.VirtualLayout(shape=(4,), dtype=f["acc/data"].dtype)
            layout[:] = h5py.VirtualSource(str(work / "base-clean.h5"), "acc/data", shape=(4,))
            del f["acc/data"]
            f["acc"].create_virtual_dataset("data", layout)
        elif how == 4:  # a huge declared shape with nothing stored
            dt = f["acc/data"].dtype
            del f["acc/data"]
            f["acc"].create_dataset("data", shape=(rng.choice([2**28, 2**40]),), dtype=dt,
                                    chunks=(64,), maxshape=(None,))
        elif how == 5:  # wrong dtypes
            del f["events/data"]
            f["events"].create_dataset("data", data=rng.choice([
                np.arange(10.0), np.zeros(3, dtype=[("host_time", "S4")]),
                np.zeros((3, 3), dtype=[("host_time", "f8")]),
                np.array([(0.0, "a")], dtype=[("host_time", "f8"),
                                              ("text", h5py.string_dtype())])]))
        elif how == 6:  # deep JSON in the summary
            f.attrs["summary"] = "[" * 100000 + "]" * 100000
        elif how == 7:
            f.attrs["schema_version"] = rng.choice([-1, 0, 2**40, 1.5, "1", np.array([1, 2])])
        else:  # wrongly typed attributes
            f.attrs["closed_cleanly"] = np.array([1, 2])
            f["gyro"].attrs["period_s"] = rng.choice(["fast", -1.0, 0.0])
            f["gyro/data"].attrs["units"] = 7


def _exercise(path: Path) -> str:
    """Open ``path`` and use what the tools use: info's description, events, phases, sysid's
    loader. Returns ``ok``/``flagged``/``refused``; raises on anything that is not a user error."""
    from cfsession import open_session
    from cfsession.errors import SessionError
    from groundstation.commands.info import describe
    from groundstation.errors import GroundStationError
    from sysid.errors import SysIdError
    from sysid.session_io import load_session

    try:
        s = open_session(path)
    except (SessionError, GroundStationError) as exc:
        one_line(exc)
        return "refused"
    json.dumps(describe(s), default=str)
    s.json_meta("summary", {})
    for stream in s.streams.values():
        if stream.kind == "log" and stream.value_fields:
            stream.values()
    try:
        load_session(path, inputs=["setpoints.roll"], outputs=["gyro.x", "gyro.y"])
    except (SysIdError, SessionError, GroundStationError) as exc:
        one_line(exc)
    return "flagged" if s.problems else "ok"


def session_reader(rng: random.Random, work: Path) -> str:
    """A damaged (flipped, overwritten, truncated) or crafted session file."""
    clean, crashed = _session_bases(work)
    path = work / "case.h5"
    if rng.random() < 0.2:
        _crafted(rng, work, path, clean)
    else:
        path.write_bytes(_mutate(rng, rng.choice([clean, crashed])))
    return _exercise(path)


# ------------------------------------------------------------------------- UDP simulator


class _ErrorLog(logging.Handler):
    """Counts log records that carry a traceback (a thread that caught the unexpected)."""

    def __init__(self) -> None:
        super().__init__(level=logging.ERROR)
        self.records: list[str] = []

    def emit(self, record: logging.LogRecord) -> None:
        if record.exc_info:
            self.records.append(self.format(record))


@functools.cache
def _udp_server() -> tuple[object, _ErrorLog, socket.socket]:
    """The server, a log handler catching tracebacks, and the client socket (kept across
    cases, so the mutated datagrams reach the vehicle rather than the foreign-sender filter)."""
    from groundstation.sim import UdpServer

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    errors = _ErrorLog()
    logging.getLogger("groundstation.sim").addHandler(errors)
    from groundstation.sim.crtp import crtp_header

    server = UdpServer(port=port, seed=1)
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    client.settimeout(2.0)
    client.sendto(bytes([crtp_header(15, 0)]) + b"hello", ("127.0.0.1", port))  # takes the link
    return server, errors, client


def _datagram(rng: random.Random) -> bytes:
    from groundstation.sim.crtp import crtp_header

    kind = rng.random()
    if kind < 0.2:  # random bytes, any length
        return rng.randbytes(rng.choice([0, 1, 2, 5, 31, 32, 200]))
    if kind < 0.7:  # a well-formed header on every service, arguments bent
        port = rng.choice([0, 2, 3, 4, 5, 6, 7, 8, 13, 14, 15])
        payload = bytes([rng.randrange(12)]) + struct.pack(
            "<H", rng.choice([0, 1, 2, 300, 0xFFFF])) + rng.randbytes(rng.randrange(0, 28))
        return bytes([crtp_header(port, rng.randrange(4))]) + payload[:30]
    if kind < 0.85:  # commander and generic setpoints with garbage numbers
        vals = [rng.choice([float("nan"), float("inf"), -1e30, 0.0, 25.0]) for _ in range(3)]
        return bytes([crtp_header(3, 0)]) + struct.pack("<fffH", *vals, rng.randrange(65536))
    # log block create/append/start with random ids, types and periods
    return bytes([crtp_header(5, 1), rng.randrange(8), rng.randrange(256)]) + rng.randbytes(
        rng.randrange(0, 29))


def udp_simulator(rng: random.Random, work: Path) -> str:
    """A burst of mutated datagrams from the client, sometimes with a second sender between;
    the server must keep serving its client and answer a probe."""
    server, errors, client = _udp_server()
    endpoint = server.endpoints[0]
    addr = ("127.0.0.1", endpoint.port)
    foreign, received = endpoint.foreign, endpoint.datagrams
    n_sent = rng.randrange(1, 40)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as other:
        n_other = 0
        for _ in range(n_sent):
            intrude = rng.random() < 0.1
            n_other += intrude
            (other if intrude else client).sendto(_datagram(rng), addr)
    client.sendto(b"\xff", addr)
    # Every datagram of this case handled before judging it (a reply byte 0xff from the vehicle
    # is no marker: an empty link packet looks the same), with a generous deadline.
    deadline = time.monotonic() + 5.0
    while endpoint.datagrams - received < n_sent + 1 and time.monotonic() < deadline:
        time.sleep(0.001)
    assert endpoint.datagrams - received >= n_sent + 1, "the server stopped receiving"
    assert endpoint._thread.is_alive() and server.simulators[0].running, "server died"
    assert not errors.records, errors.records[0]
    if endpoint.client is None or endpoint.client[1] == client.getsockname()[1]:
        assert endpoint.foreign - foreign <= n_other, "a client datagram was taken as foreign"
        return "intruded" if n_other else "ok"
    # The client (kept across cases) was silent past CLIENT_SILENCE_S on a busy host, so an
    # intruder legitimately took the free link; the client is then foreign until it frees again.
    assert n_other, "the link changed hands with no other sender"
    return "taken over"


# ------------------------------------------------------------------------- importers


def importers(rng: random.Random, work: Path) -> str:
    """A mutated cfclient CSV or uSD log through ``groundstation import`` (the cases of
    ``tests/importers/fuzz.py``): a readable, cleanly closed session or one error line."""
    from tests.importers.fuzz import case

    folder = Path(tempfile.mkdtemp(dir=work))
    try:
        src, outcome = case(rng.getrandbits(32), rng.randrange(2), folder)  # index 1: uSD
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    assert not outcome.problem, f"{src.name}: {outcome.problem}"
    return "imported" if outcome.ok else "refused"


# ------------------------------------------------------------------------- model files


@functools.cache
def _model_bases(work: Path) -> dict[str, bytes]:
    """A small identified-looking model (names, units, provenance) in each of its formats."""
    import numpy as np

    from sysid.model import StateSpaceModel

    rng = np.random.default_rng(0)
    model = StateSpaceModel(
        A=np.diag([0.9, 0.5, -0.3]), B=rng.standard_normal((3, 2)), C=rng.standard_normal((2, 3)),
        D=np.zeros((2, 2)), K=0.1 * rng.standard_normal((3, 2)), dt=0.02,
        input_names=["motor.m1", "motor.m2"], output_names=["gyro.x", "gyro.z"],
        provenance={"method": "iem", "order": 3, "past": 10, "future": 5,
                    "singular_values": [3.0, 2.0, 1.0, 0.1, 0.05],
                    "fit_percent": {"simulation": {"gyro.x": 80.0, "gyro.z": 40.0}}})
    out = {}
    for suffix in (".h5", ".json", ".mat"):
        path = work / f"model-clean{suffix}"
        model.save(path)
        out[suffix] = path.read_bytes()
    return out


def model_reader(rng: random.Random, work: Path) -> str:
    """A damaged model file (HDF5, JSON or MAT) through what reads one: ``sysid``'s loader, the
    model's poles and a simulation (``sysid compare``), and ``plan design``'s facts."""
    import numpy as np

    import sysid
    from groundstation.plan.design import ModelFacts
    from sysid.errors import SysIdError

    suffix, clean = rng.choice(sorted(_model_bases(work).items()))
    path = work / f"case{suffix}"
    path.write_bytes(_mutate(rng, clean))
    try:
        model = sysid.load_model(path)
    except SysIdError as exc:
        one_line(exc)
        return "refused"
    model.poles()
    ModelFacts.from_model(model, source=path.name)
    data = sysid.IOData(u=np.ones((50, model.n_inputs)), y=np.ones((50, model.n_outputs)),
                        dt=model.dt)
    try:
        sysid.compare(model, data, horizon=1, warn=False)
    except SysIdError as exc:
        one_line(exc)
    return "read"


TARGETS: dict[str, Target] = {"session": session_reader, "udp": udp_simulator,
                              "importers": importers, "model": model_reader}


# ------------------------------------------------------------------------- running


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
