"""cfclient against the simulator: every log variable and parameter its flight tab, battery bar
and supervisor view read is in the simulated TOCs, typed, and moves when the vehicle does."""

from __future__ import annotations

import time

import pytest

import groundstation.sim as gsim
from groundstation.flight.clock import clock_for_uri

from .cfclient_reads import CFCLIENT_DECKS, CFCLIENT_LOG_VARIABLES, CFCLIENT_PARAMS
from .helpers import Recorder, connect, fly


def test_everything_cfclient_reads_is_in_the_tocs(sim_uri):
    with connect(sim_uri) as scf:
        log_toc, param_toc = scf.cf.log.toc, scf.cf.param.toc
        missing = [n for n in CFCLIENT_LOG_VARIABLES
                   if log_toc.get_element_by_complete_name(n) is None]
        assert not missing
        assert "deck" in param_toc.toc  # cfclient: KeyError 'deck' without it
        for name in (*(f"deck.{d}" for d in CFCLIENT_DECKS), *CFCLIENT_PARAMS):
            assert param_toc.get_element_by_complete_name(name) is not None, name
        assert all(int(scf.cf.param.get_value(f"deck.{d}")) == 0 for d in CFCLIENT_DECKS)


def test_flight_tab_values_follow_the_vehicle(sim_uri):
    """The attitude indicator's, motor bars' and supervisor's variables carry the vehicle's state:
    at rest level and ready (can fly, auto-armed, not flying); in flight the estimated roll
    follows the setpoint, the desired roll is the setpoint, the supervisor says flying."""
    blocks = {"att": ["stateEstimate.roll", "stateEstimate.pitch", "controller.roll"],
              "sup": ["supervisor.info", "sys.canfly", "sys.isFlying", "pm.state"]}
    with connect(sim_uri) as scf:
        cf, sim = scf.cf, gsim.instance(sim_uri)
        rec = Recorder(cf, blocks=blocks, period_ms=20)
        _, sup = _wait_rows(rec, "sup")
        info = int(sup[-1, 0])
        assert info & 0b1111 == 0b1110 and not info & 0x50  # armed, auto, can fly (SITL: 14)
        assert sup[-1, 1] == 1 and sup[-1, 2] == 0 and sup[-1, 3] == 0
        thrust = sim.vehicle.hover_thrust() + 3000
        fly(cf, clock_for_uri(sim_uri), [(0.1, 0, 0, 0, 0), (1.5, 8.0, 0, 0, thrust)])
        _, att = _wait_rows(rec, "att")
        _, sup = _wait_rows(rec, "sup")
        cf.commander.send_stop_setpoint()
        assert att[-1, 2] == pytest.approx(8.0)          # controller.roll: the setpoint
        assert att[-1, 0] == pytest.approx(8.0, abs=2.0)  # stateEstimate.roll follows
        assert int(sup[-1, 0]) & 0x10 and sup[-1, 2] == 1  # flying


def _wait_rows(rec: Recorder, name: str, timeout_s: float = 5.0):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        t, v = rec.rows(name)
        if len(t):
            return t, v
        time.sleep(0.02)
    raise AssertionError(f"no {name} rows")
