"""The simulator's TOCs against the real firmware's (pinned SITL build, read with cflib): every
simulated variable and parameter the real firmware has is there with the same type; the others
belong to hardware drivers the SITL build leaves out (``pm``, ``pwm``, ``deck``). cfclient's
variables are all in the real TOC except the power-management ones."""

from __future__ import annotations

from groundstation.sim.vehicle import SimVehicle

from ..sim_crtp.cfclient_reads import CFCLIENT_LOG_VARIABLES
from ..sim_crtp.helpers import connect
from . import backend

HARDWARE_ONLY = {"pm", "pwm", "deck"}


def test_simulated_tocs_agree_with_the_real_firmware():
    try:
        v = backend.start_vehicle()
        with connect(v.uri) as scf:
            log = {f"{g}.{n}": e.ctype for g, d in scf.cf.log.toc.toc.items()
                   for n, e in d.items()}
            params = {f"{g}.{n}": e.ctype for g, d in scf.cf.param.toc.toc.items()
                      for n, e in d.items()}
    finally:
        backend.close_all()
    # The pinned build (shared/sitl/README.md): 337 variables in 33 groups, 205 parameters.
    assert (len(log), len(params)) == (337, 205)
    for simulated, real in ((SimVehicle.LOG_VARIABLES, log), (SimVehicle.PARAMS, params)):
        wrong = {n: (t, real[n]) for n, t in simulated.items() if n in real and real[n] != t}
        assert not wrong
        absent = {n.split(".")[0] for n in simulated if n not in real}
        assert absent <= HARDWARE_ONLY, absent
    assert [n for n in CFCLIENT_LOG_VARIABLES if n not in log] == [
        "pm.vbat", "pm.state", "pm.batteryLevel"]
