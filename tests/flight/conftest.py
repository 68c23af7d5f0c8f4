"""Fixtures for flights against the simulated Crazyflie: a fresh ``sim://`` URI per test at 20x
real time, every simulation powered off afterwards, and helpers that read the simulator's side.

``flight_uri`` is the same factory for one backend per parameter (python-can's back-to-back
style), :data:`BACKENDS`: ``sim`` (``sim://``), ``sitl`` (the real firmware with our physics on
``udp://127.0.0.1:P``, real time; skipped when ``make sitl`` has not built it) or ``radio``
(``radio://0/80/2M/E7E7E7E7E7`` through unmodified cflib and an emulated Crazyradio PA to a
simulated vehicle at up to 20x, ``tests/sim_radio/backend.py``; one vehicle per test). A test
that takes ``flight_uri`` runs on every backend; :func:`backends` skips the ones it names, each
with its reason (a reason in the report, never a silent omission).

``sim_uri`` (``sim://`` only) serves the tests whose subject is not the link: command-line
options, output files, the live view; ``udp://`` against :class:`~groundstation.sim.UdpServer` is
tested in ``test_link_watch.py``."""

from __future__ import annotations

import itertools
import time

import pytest

import groundstation.sim as gsim
from groundstation.flight.link import install_drivers
from groundstation.plan import load_plan, parse_plan

SPEED = 20
BACKENDS = ("sim", "sitl", "radio")
SITL_COST = ("real-time firmware: a whole plan costs its length (42-112 s); SITL flies hover-check "
             "and every safety path here, and the thesis experiment is docs/sitl.md's")
SITL_HOST_SIDE = ("the ground station's own path, nothing in it the firmware does otherwise; SITL "
                  "flies the abort paths that end in the firmware (a signal, a rate limit, the "
                  "stop policy, a low battery) and a whole flight")
SITL_AS_SIGNAL = ("the firmware gets the same descent, stop and stop feed as after a signal, "
                  "which SITL flies (test_safety_signals); the cause is the ground station's")
SIM_HOOK = "the test drives the vehicle through the sim:// registry (groundstation.sim.instance)"
_counter = itertools.count(500)


def backends(**skip: str) -> pytest.MarkDecorator:
    """Parametrise ``flight_uri`` over :data:`BACKENDS`, skipping those named with the stated
    reason: ``@backends(sitl=SIM_HOOK)``."""
    unknown = set(skip) - set(BACKENDS)
    assert not unknown, f"no such backend: {unknown}"
    return pytest.mark.parametrize("flight_uri", [
        pytest.param(b, marks=pytest.mark.skip(reason=f"{b}: {skip[b]}")) if b in skip else b
        for b in BACKENDS], indirect=True)


@pytest.fixture
def sim_uri():
    """A ``sim://`` URI no other test uses (``sim_uri(**faults)`` adds options)."""
    install_drivers()

    def make(**options: float) -> str:
        query = "&".join(f"{k}={v}" for k, v in {"speed": SPEED, **options}.items())
        return f"sim://{next(_counter)}?{query}"

    yield make
    gsim.close_all()


@pytest.fixture(params=BACKENDS)
def flight_uri(request):
    """A factory of fresh vehicle URIs on the backend named by the parameter (``radio``: noise
    ``loss``, ``bit_error_rate`` and ``seed`` of the emulated dongle)."""
    if request.param == "sim":
        yield request.getfixturevalue("sim_uri")
        return
    if request.param == "radio":
        from ..sim_radio import backend as radio

        yield lambda **noise: radio.start_vehicle(**noise)
        radio.close_all()
        return
    from ..sitl import backend

    def make(**faults: float) -> str:
        assert not faults, "the sitl backend has no fault options"
        return backend.start_vehicle().uri

    yield make
    backend.close_all()


def wait_for_stop(uri: str, timeout_s: float = 5.0) -> gsim.Simulator:
    """The simulation behind ``uri`` once its motors are off and it counted a stop (``udp://``:
    the SITL vehicle once the firmware's motor commands are zero; ``radio://``: the simulation
    behind the emulated dongle)."""
    if uri.startswith("radio://"):
        from ..sim_radio import backend as radio

        return radio.wait_for_stop(uri).sim
    if uri.startswith("udp://"):
        from ..sitl import backend

        return backend.wait_for_stop(uri)  # type: ignore[return-value]
    sim = gsim.instance(uri)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        v = sim.vehicle
        if v.stop_count >= 1 and not any(v.motors_pwm):
            return sim
        time.sleep(0.01)
    raise AssertionError(f"vehicle not stopped: motors {sim.vehicle.motors_pwm}, "
                         f"stop_count {sim.vehicle.stop_count}")


def wall_slack_s(uri: str) -> float:
    """Extra seconds a timing bound allows on a wall-clock backend (``udp://``: SITL, real time,
    where a busy host delays single sends); 0 where the simulation clock waits for the flight."""
    return 0.4 if uri.startswith("udp://") else 0.0


def one_variant_on_sitl(request: pytest.FixtureRequest, *, first: bool, why: str) -> None:
    """Skip a test's other variants on ``sitl``, with ``why`` as the reason: the real-time
    firmware is one serial scope of the suite (``tests/conftest.py``), where a flight costs its
    length, and variants that differ only on the ground station's side (which ``sim`` and
    ``radio`` run in full) fly once there. ``first`` says this variant is the one kept."""
    if not first and request.node.callspec.params.get("flight_uri") == "sitl":
        pytest.skip(f"sitl: {why}; the other variant flies here, every variant on sim and radio")


def plan_variant(name: str, **replace: str):
    """A shipped plan with text replaced (``old=new`` pairs given as ``{old: new}``)."""
    base = load_plan(name)
    text = base.text
    for old, new in replace.items():
        assert old in text, old
        text = text.replace(old, new)
    return parse_plan(text=text, source=f"{name}-variant", name=base.name)


class AfterLanding:
    """A listener that does ``action()`` once, when the landed flight's "flight complete"
    event is recorded (the stop delivered, the file's tail recording)."""

    def __init__(self, action) -> None:
        self.action, self.done = action, False

    def begin(self, **_kw) -> None: ...
    def end(self, **_kw) -> None: ...

    def rows(self, *, stream, rows) -> None:
        if stream == "events" and not self.done and any(b"flight complete" in bytes(r[3])
                                                         for r in rows):
            self.done = True
            self.action()
