"""Arming, emergency stop and notify-stop reach the simulated firmware through cflib's own calls."""

from __future__ import annotations

import groundstation.sim as gsim

from .helpers import connect, fly


def test_disarmed_vehicle_keeps_its_motors_off_until_armed(sim_uri):
    with connect(sim_uri) as scf:
        cf, sim = scf.cf, gsim.instance(sim_uri)
        cf.supervisor.send_arming_request(False)
        fly(cf, sim.clock, [(0.2, 0, 0, 0, 0), (0.5, 0, 0, 0, 30000)])
        assert sim.vehicle.motors_pwm == (0, 0, 0, 0)
        assert sim.vehicle.supervisor_state == "PreFlChecksPassed"
        cf.supervisor.send_arming_request(True)
        fly(cf, sim.clock, [(0.5, 0, 0, 0, 30000)])
        assert min(sim.vehicle.motors_pwm) > 20000


def test_notify_setpoint_stop_lets_the_setpoint_expire(sim_uri):
    with connect(sim_uri) as scf:
        cf, sim = scf.cf, gsim.instance(sim_uri)
        clock = sim.clock
        # the firmware backdates the setpoint by min(2000 - remain, uptime) ms: be > 2 s old
        clock.sleep_until(2.5)
        fly(cf, clock, [(0.2, 0, 0, 0, 0), (0.5, 0, 0, 0, 30000)])  # on the ground, motors on
        assert min(sim.vehicle.motors_pwm) > 20000
        cf.commander.send_notify_setpoint_stop(remain_valid_milliseconds=100)
        t = clock.now()
        clock.sleep_until(t + 0.05)
        assert min(sim.vehicle.motors_pwm) > 20000  # still valid for 100 ms ...
        clock.sleep_until(t + 0.3)
        assert sim.vehicle.motors_pwm == (0, 0, 0, 0)  # ... then the null setpoint


def test_an_emergency_stop_locks_the_vehicle_until_restarted(sim_uri):
    """cflib's ``send_emergency_stop``: the firmware keeps the request and locks; setpoints
    sent after it (even a zero-thrust one, which unlocks a thrust lock) run no motor."""
    with connect(sim_uri) as scf:
        cf, sim = scf.cf, gsim.instance(sim_uri)
        fly(cf, sim.clock, [(0.2, 0, 0, 0, 0), (0.5, 0, 0, 0, 30000)])
        assert min(sim.vehicle.motors_pwm) > 20000
        cf.supervisor.send_emergency_stop()
        fly(cf, sim.clock, [(0.3, 0, 0, 0, 0), (0.5, 0, 0, 0, 30000)])
        assert sim.vehicle.motors_pwm == (0, 0, 0, 0) and sim.vehicle.is_locked
