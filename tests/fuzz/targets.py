"""The fuzz harness's targets, registered in :data:`TARGETS`: ``target(rng, work) -> outcome``
makes one case (a mutated input, from ``rng`` only, so a seed replays a run; the mutators are
:mod:`tests.fuzz.mutators`), feeds it to the code under test and returns a short outcome label
(``"ok"``, ``"flagged"``, ``"refused"``, ...). A user error must be one line (:func:`one_line`);
anything else that escapes is a failure. The runner: :mod:`tests.fuzz.harness`.

Add a target: write ``def my_target(rng, work) -> str`` here and add it to :data:`TARGETS`.
"""

from __future__ import annotations

import functools
import json
import logging
import random
import re
import shutil
import socket
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from tests.fuzz.mutators import crafted_session, datagram, mutate, plan_text

Target = Callable[[random.Random, Path], str]


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


def _info_cli(path: Path, args: list[str]) -> None:
    """``groundstation info`` on ``path`` as a user runs it (the text tables through rich, or
    ``--json``): exit 0, or exit 2 with one ``error:`` line; anything else raises."""
    from click.testing import CliRunner

    from groundstation.cli import main

    result = CliRunner().invoke(main, ["info", *args, str(path)])
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    assert "Traceback" not in result.output, result.output[-2000:]
    if result.exit_code:
        assert result.exit_code == 2 and result.stderr.count("\n") == 1, result.output[-1000:]
        assert result.stderr.startswith("error: "), result.stderr[:500]
        one_line(ValueError(result.stderr.rstrip("\n")))


def _exercise(path: Path, *, info: list[str] | None = None) -> str:
    """Open ``path`` and use what the tools use: info's description, events, phases, sysid's
    loader; with ``info`` (its options), ``groundstation info`` itself. Returns
    ``ok``/``flagged``/``refused``; raises on anything that is not a user error."""
    from cfsession import open_session
    from cfsession.errors import SessionError
    from groundstation.commands.info import describe
    from groundstation.errors import GroundStationError
    from sysid.errors import SysIdError
    from sysid.session_io import load_session

    if info is not None:
        _info_cli(path, info)
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
    """A damaged (flipped, overwritten, truncated) or crafted session file; a crafted one also
    through ``groundstation info`` (text with ``--events``, or ``--json``), which shows the
    file's own text and attributes."""
    clean, crashed = _session_bases(work)
    path = work / "case.h5"
    if rng.random() < 0.2:
        crafted_session(rng, work, path, clean)
        return _exercise(path, info=rng.choice([["--events"], ["--json", "--events"]]))
    path.write_bytes(mutate(rng, rng.choice([clean, crashed])))
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
            (other if intrude else client).sendto(datagram(rng), addr)
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
    path.write_bytes(mutate(rng, clean))
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


# ------------------------------------------------------------------------- flight plans

PLAN_MEMORY_BYTES = 1 << 30
"""Address space a plan case may add to the child's (a refused plan needs none of it; the
largest valid schedule, 360 000 setpoints, a few MB): beyond it numpy raises MemoryError, a
failure, rather than the host swapping."""


@functools.cache
def _plan_bases() -> tuple[str, ...]:
    """The shipped plans' texts; on first use, the child's address space is capped
    (:data:`PLAN_MEMORY_BYTES` above what it has mapped), so a plan that asks for a huge
    schedule fails its case instead of exhausting the host."""
    import resource

    from groundstation.cli import main  # noqa: F401  (mapped before the cap)
    from groundstation.plan import SHIPPED_PLANS_DIR

    try:  # Linux: the pages mapped now
        with open("/proc/self/statm") as fh:
            mapped = int(fh.read().split()[0]) * resource.getpagesize()
    except OSError:
        mapped = None
    if mapped is not None:
        resource.setrlimit(resource.RLIMIT_AS, (mapped + PLAN_MEMORY_BYTES, resource.RLIM_INFINITY))
    return tuple(p.read_text() for p in sorted(SHIPPED_PLANS_DIR.glob("*.toml")))


def plan_reader(rng: random.Random, work: Path) -> str:
    """A shipped plan's TOML bent (:func:`~tests.fuzz.mutators.plan_text`) through what a user
    runs: ``load_plan``, the schedule (compiled, an abort's descent), ``plan check``'s summary,
    and ``groundstation plan check`` itself (text or ``--json``), which must agree: ``ok`` or
    ``refused`` with one line (exit 2). A plan that loads must compile: an error there, even a
    PlanError, is a failure (the loader checks every value, naming its key and line)."""
    from click.testing import CliRunner

    from groundstation.cli import main
    from groundstation.commands.plan import summarize
    from groundstation.errors import PlanError
    from groundstation.plan import load_plan

    path = work / "case.toml"
    path.write_bytes(plan_text(rng, rng.choice(_plan_bases())))
    try:
        plan = load_plan(path)
    except PlanError as exc:
        one_line(exc)
        outcome = "refused"
    else:
        schedule = plan.compile()
        schedule.abort_schedule(rng.randrange(len(schedule) + 1))
        json.dumps(summarize(plan, schedule))
        outcome = "ok"
    args = ["plan", "check", *(["--json"] if rng.random() < 0.3 else []), str(path)]
    result = CliRunner().invoke(main, args)
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    cli = {0: "ok", 2: "refused"}.get(result.exit_code, f"exit {result.exit_code}")
    if outcome == "ok" and plan.live_id is not None and re.match(
            r"error: (.*:\d+: )?live_id[.:]", result.stderr):  # fly's checks of live
        outcome = "refused"  # identification, which plan check runs on a plan with a
        # [live_id] table, naming its key and line (docs/live-id.md); the loader does not
    assert cli == outcome, f"plan check says {cli}, load_plan {outcome}: {result.output[-500:]}"
    if cli == "refused":
        assert result.stderr.count("\n") == 1 and result.stderr.startswith("error: "), (
            result.stderr[:500])
    return outcome


TARGETS: dict[str, Target] = {"session": session_reader, "udp": udp_simulator,
                              "importers": importers, "model": model_reader, "plan": plan_reader}
