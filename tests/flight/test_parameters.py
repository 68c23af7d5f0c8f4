"""A plan's ``[parameters]``: set in the firmware for the flight, put back after the stop.

Known truth: the firmware's own parameter values, read over a second cflib connection after
the flight (every backend) and from the simulated vehicle during it (``sim://``).
"""

from __future__ import annotations

import dataclasses
import json
import re

import pytest
from cflib.crazyflie import Crazyflie
from cflib.crazyflie.syncCrazyflie import SyncCrazyflie
from click.testing import CliRunner

import groundstation.sim as gsim
from groundstation.cli import main
from groundstation.errors import LinkError
from groundstation.flight import fly_plan
from groundstation.flight.drivers import toc_cache_dir
from groundstation.plan import load_plan, parse_plan

from .checks import check_closed_with_stop
from .conftest import wait_for_stop

SET = "\n[parameters]\npid_attitude.yaw_kd = 0.0\npid_rate.yaw_kp = 100\n"
NAMES = ("pid_attitude.yaw_kd", "pid_rate.yaw_kp")


def _plan(extra: str = SET, name: str = "hover-check"):
    """``name`` with a 2 s hover and a 1 s landing (the firmware in the loop flies in real
    time) and ``extra``."""
    text = load_plan(name).text.replace("duration = 5.0 ", "duration = 2.0 ", 1)
    text = text.replace("duration = 3.0 ", "duration = 1.0 ", 1)  # the landing
    return parse_plan(text=text + extra, source=f"{name}+parameters", name=name)


def _read_back(uri: str) -> dict[str, float]:
    """The values in the firmware, read over a second connection (its TOCs from the run's
    cache, as the flight's connect took them: the values themselves are read at connect)."""
    cache = toc_cache_dir()
    with SyncCrazyflie(uri, cf=Crazyflie(rw_cache=None if cache is None else str(cache))) as scf:
        return {n: float(scf.cf.param.get_value(n)) for n in NAMES}


def _index(texts: list[str], start: str) -> int:
    return next(i for i, t in enumerate(texts) if t.startswith(start))


def test_parameters_are_set_for_the_flight_and_restored_after_it(flight_uri, tmp_path):
    uri = flight_uri()
    during: list[float] = []

    def hook(k: int) -> None:
        if k == 30 and uri.startswith("sim://"):
            during.append(gsim.instance(uri).vehicle.read_param("pid_attitude.yaw_kd"))

    result = fly_plan(plan=_plan(), out=tmp_path, uri=uri, tick_hook=hook)
    assert not result.aborted, result.cause
    wait_for_stop(uri)
    s = check_closed_with_stop(result)
    texts = [e.text for e in s.events()]
    set_at = _index(texts, "parameters set for the flight: pid_attitude.yaw_kd = 0 (was 0.35), "
                           "pid_rate.yaw_kp = 100 (was 120)")
    back = _index(texts, "parameters restored: pid_attitude.yaw_kd = 0.35, pid_rate.yaw_kp = 120")
    assert set_at < _index(texts, "phase takeoff") < _index(texts, "stop setpoint sent") < back
    meta = s.meta["plan_parameters"]
    meta = json.loads(meta) if isinstance(meta, str) else meta
    assert meta["pid_rate.yaw_kp"] == {"value": 100.0, "was": 120.0}
    assert meta["pid_attitude.yaw_kd"]["was"] == pytest.approx(0.35)
    assert _read_back(uri) == {"pid_attitude.yaw_kd": pytest.approx(0.35),
                               "pid_rate.yaw_kp": 120.0}
    if uri.startswith("sim://"):
        assert during == [0.0]
    info = CliRunner().invoke(main, ["info", str(result.path)])
    assert "firmware parameters for the flight: pid_attitude.yaw_kd = 0 (was 0.35)" in info.output
    as_json = json.loads(CliRunner().invoke(main, ["info", str(result.path), "--json"]).stdout)
    assert as_json["parameters"]["pid_rate.yaw_kp"] == {"value": 100.0, "was": 120.0}


def test_an_aborted_flight_restores_them_after_the_stop(sim_uri, tmp_path):
    uri = sim_uri()

    def hook(k: int) -> None:
        if k == 25:
            raise RuntimeError("injected fault")

    result = fly_plan(plan=_plan(), out=tmp_path, uri=uri, tick_hook=hook)
    assert result.aborted and "injected fault" in result.cause
    wait_for_stop(uri)
    texts = [e.text for e in check_closed_with_stop(result).events()]
    assert _index(texts, "stop setpoint sent") < _index(texts, "parameters restored")
    assert gsim.instance(uri).vehicle.read_param("pid_rate.yaw_kp") == 120.0


def test_a_lost_link_leaves_them_set_and_says_so(sim_uri, tmp_path):
    """No link after the flight: nothing can be written back; a warning names the values the
    firmware keeps until it restarts (they were never left unrecorded)."""
    uri = sim_uri()

    def cut(k: int) -> None:  # in flight, whatever the connect and the writes took (a cut at a
        if k == 10:  # fixed simulated time could come before them on a busy host)
            gsim.instance(uri).cut_link()

    result = fly_plan(plan=_plan(), out=tmp_path, uri=uri, tick_hook=cut)
    assert result.aborted and "link lost" in result.cause, result.cause
    events = [e for e in check_closed_with_stop(result).events()
              if e.text.startswith("parameters not restored")]
    assert len(events) == 1 and events[0].level == "warning" and events[0].source == "safety"
    assert "pid_attitude.yaw_kd = 0.35, pid_rate.yaw_kp = 120 until the Crazyflie restarts" in (
        events[0].text)
    assert gsim.instance(uri).vehicle.read_param("pid_rate.yaw_kp") == 100.0  # still set


@pytest.mark.parametrize(("extra", "needle"), [
    ("\n[parameters]\npid_attitude.no_such = 1.0\n", "has no parameter 'pid_attitude.no_such'"),
    ("\n[parameters]\nfirmware.revision0 = 1\n", "firmware.revision0 is read-only"),
])
def test_a_parameter_the_firmware_cannot_take_is_one_line_and_nothing_flown(
        sim_uri, tmp_path, extra, needle):
    uri = sim_uri()
    with pytest.raises(LinkError, match="plan \\[parameters\\]"):
        fly_plan(plan=_plan(extra), out=tmp_path / "api", uri=uri)
    plan = tmp_path / "p.toml"
    plan.write_text(_plan(extra).text, encoding="utf-8")
    out = tmp_path / "cli"
    res = CliRunner().invoke(main, ["fly", str(plan), "--uri", sim_uri(), "--out", str(out)])
    assert res.exit_code != 0 and needle in res.output and res.output.count("\n") == 1, res.output
    assert not list(tmp_path.rglob("*.h5"))  # nothing recorded, nothing flown
    assert gsim.instance(uri).vehicle.read_param("pid_rate.yaw_kp") == 120.0


def _past_the_loader(name: str, value: float):
    """A plan whose ``[parameters]`` the loader did not check: the types it knows offline
    (``groundstation.plan.param_types``) may not be the flown firmware's, whose TOC decides."""
    return dataclasses.replace(_plan(""), parameters=((name, value),))


def test_a_fraction_for_an_integer_parameter_is_refused_after_connect(sim_uri, tmp_path):
    uri = sim_uri()
    with pytest.raises(LinkError, match=r"plan \[parameters\]: stabilizer\.estimator.*1\.5"):
        fly_plan(plan=_past_the_loader("stabilizer.estimator", 1.5), out=tmp_path, uri=uri)
    assert not list(tmp_path.rglob("*.h5"))


@pytest.mark.parametrize(("name", "value", "needle"), [
    ("stabilizer.estimator", 300.0, "300 is outside uint8_t's range 0 to 255"),
    ("stabilizer.estimator", -1.0, "-1 is outside uint8_t's range 0 to 255"),
    ("pid_attitude.yaw_kd", 1e39, "1e+39 is outside float's range"),
])
def test_a_value_beyond_the_firmwares_type_is_refused_after_connect_before_take_off(
        sim_uri, tmp_path, name, value, needle):
    """The TOC's type decides where the loader does not know it: one line before anything is
    recorded or written, not cflib's struct.error after the take-off checks (audit)."""
    uri = sim_uri()
    with pytest.raises(LinkError, match=re.escape(f"plan [parameters]: {name}: {needle}")):
        fly_plan(plan=_past_the_loader(name, value), out=tmp_path, uri=uri)
    assert not list(tmp_path.rglob("*.h5"))  # nothing recorded, nothing flown
    assert gsim.instance(uri).vehicle.read_param("stabilizer.estimator") == 1.0


HUGE = "1" + "0" * 400  # a JSON integer float() cannot hold (OverflowError)


@pytest.mark.parametrize("meta", ["{not json", '["a"]', {"a.b": {"value": "x", "was": 1}},
                                  {"a.b": {"value": True, "was": 1.0}}, {"a.b": 3},
                                  '{"a.b": {"value": ' + HUGE + ', "was": 1.0}}',
                                  '{"a.b": {"value": Infinity, "was": 1.0}}'])
def test_info_reads_a_hostile_parameters_attribute_without_failing(tmp_path, meta):
    from groundstation.commands.plan_design import _flown_firmware
    from tests.sysid.flights import known_system, write_flight

    flight = write_flight(tmp_path / "f.h5", system=known_system(), seed=0, n=600,
                          metadata={"plan_parameters": meta,
                                    "params": '{"pid": {"kd": ' + HUGE + ', "kp": 2.5}}'})
    assert _flown_firmware((flight.path,)) == {"pid.kp": 2.5}  # what plan design sees
    res = CliRunner().invoke(main, ["info", str(flight.path), "--json"])
    assert res.exit_code == 0, res.output
    assert "parameters" not in json.loads(res.stdout)
    text = CliRunner().invoke(main, ["info", str(flight.path)])
    assert text.exit_code == 0 and "firmware parameters" not in text.output
