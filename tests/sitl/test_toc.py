"""The simulator's TOCs against the real firmware's (pinned SITL build, read with cflib): every
simulated variable and parameter the real firmware has is there with the same type; the others
belong to the PWM driver the SITL build leaves out. Every variable and parameter cfclient reads is
in the real TOC, power management (``tools/sitl-pm-battery.patch``) and the ``deck`` group
(``tools/sitl-deck-params.patch``) too, and the battery it shows is the physics peer's."""

from __future__ import annotations

import time

from groundstation.sim.vehicle import SimVehicle

from ..sim_crtp.cfclient_reads import CFCLIENT_DECKS, CFCLIENT_LOG_VARIABLES, CFCLIENT_PARAMS
from ..sim_crtp.helpers import Recorder, connect
from . import backend

HARDWARE_ONLY = {"pwm"}

PM = ["pm.vbat", "pm.vbatMV", "pm.state", "pm.batteryLevel"]


def read_once(scf, names: list[str]) -> dict[str, float]:
    """The first sample of ``names`` from a 10 Hz log block (waits up to 20 s)."""
    rec = Recorder(scf.cf, blocks={"one": names}, period_ms=100)
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        _, values = rec.rows("one")
        if len(values):
            return dict(zip(names, values[0], strict=True))
        time.sleep(0.05)
    raise AssertionError(f"no sample of {names} within 20 s")


def test_simulated_tocs_agree_with_the_real_firmware():
    try:
        v = backend.start_vehicle()
        with connect(v.uri) as scf:
            log = {f"{g}.{n}": e.ctype for g, d in scf.cf.log.toc.toc.items()
                   for n, e in d.items()}
            params = {f"{g}.{n}": e.ctype for g, d in scf.cf.param.toc.toc.items()
                      for n, e in d.items()}
            pm = read_once(scf, PM)
            decks = dict(scf.cf.param.values["deck"])  # read at connect (as strings)
    finally:
        backend.close_all()
    # The pinned build (shared/sitl/README.md): 337 variables in 33 groups, 205 parameters;
    # the pm patch adds 4 variables and 2 parameters, the deck patch 10 parameters.
    assert (len(log), len(params)) == (341, 217)
    for simulated, real in ((SimVehicle.LOG_VARIABLES, log), (SimVehicle.PARAMS, params)):
        wrong = {n: (t, real[n]) for n, t in simulated.items() if n in real and real[n] != t}
        assert not wrong
        absent = {n.split(".")[0] for n in simulated if n not in real}
        assert absent <= HARDWARE_ONLY, absent
    assert [n for n in CFCLIENT_LOG_VARIABLES if n not in log] == []
    wanted = [*CFCLIENT_PARAMS, *(f"deck.{d}" for d in CFCLIENT_DECKS)]
    assert [n for n in wanted if n not in params] == []
    assert {float(v) for v in decks.values()} == {0.0}  # a bare Crazyflie: no deck attached
    # the peer's full battery at rest (4.15 V), as cfclient's battery bar shows it
    assert 4.0 < pm["pm.vbat"] <= 4.15 and abs(pm["pm.vbatMV"] - 1000 * pm["pm.vbat"]) <= 1
    assert (pm["pm.state"], pm["pm.batteryLevel"]) == (0, 90)
