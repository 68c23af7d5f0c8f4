"""``[parameters]`` values against the firmware parameter's type: a value the type cannot hold
(beyond its range, a fraction for an integer) is refused when the plan loads where the type is
known offline (``plan check``, and ``fly`` before connecting), one line naming the parameter,
the value and the range. Before, it passed and the flight aborted after connecting with
cflib's ``struct.error`` traceback (the audit's ``stabilizer.estimator = 300``).

Known truth: ``struct.pack`` with cflib's codes, which is what cflib sends the value with."""

from __future__ import annotations

import re
import struct

import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.errors import PlanError
from groundstation.plan import parse_plan
from groundstation.plan.param_types import CTYPES, KNOWN_TYPES, type_range, value_problem
from groundstation.sim.vehicle_toc import PARAMS, PARAMS_READ_ONLY
from tests.plan.conftest import BASE, line_of

BAD = [
    ("stabilizer.estimator = 300", "300 is outside uint8_t's range 0 to 255"),
    ("stabilizer.estimator = 256", "256 is outside uint8_t's range 0 to 255"),
    ("stabilizer.estimator = -1", "-1 is outside uint8_t's range 0 to 255"),
    ("stabilizer.estimator = 1.5", "1.5 is not an integer (uint8_t, 0 to 255)"),
    ("pid_rate.rateFiltEn = 128", "128 is outside int8_t's range -128 to 127"),
    ("posCtlPid.thrustBase = 65536", "65536 is outside uint16_t's range 0 to 65535"),
    ("powerDist.idleThrust = 4294967296", "4294967296 is outside uint32_t's range 0 to 4294967295"),
    ("pid_attitude.yaw_kd = 1e39", "1e+39 is outside float's range ±3.4028235e+38"),
    ("pid_attitude.yaw_kd = -3.4028236e38",
     "-3.4028236e+38 is outside float's range ±3.4028235e+38"),
]


def _packs(value: float, ctype: str) -> bool:
    code = CTYPES[ctype]
    try:
        struct.pack(code, float(value) if code in ("<e", "<f", "<d") else int(value))
    except (OverflowError, struct.error):
        return False
    return True


@pytest.mark.parametrize("ctype", sorted(CTYPES))
def test_the_range_is_what_cflib_can_pack(ctype):
    lo, hi = type_range(ctype)
    assert value_problem(lo, ctype) == value_problem(hi, ctype) == ""
    assert _packs(lo, ctype) and _packs(hi, ctype)
    if ctype == "double":
        return  # every finite float is a double
    for beyond in ((2 * lo, 2 * hi) if ctype in ("FP16", "float") else (lo - 1, hi + 1)):
        assert value_problem(beyond, ctype) and not _packs(beyond, ctype)


@pytest.mark.parametrize("value", [0.0, -0.0, 1.0, 3.4028234663852886e38, 3.4028235e38, 1e-50,
                                   3.4028235677973366e38, -3.4028235677973366e38, 65504.0,
                                   65519.0, 65520.0])
@pytest.mark.parametrize("ctype", ["float", "FP16"])
def test_a_float_is_refused_exactly_when_it_does_not_pack(value, ctype):
    assert (value_problem(value, ctype) == "") == _packs(value, ctype)


def test_the_known_types_agree_with_the_simulated_firmware():
    shared = {n: t for n, t in KNOWN_TYPES.items() if n in PARAMS}
    assert shared and all(PARAMS[n] == t for n, t in shared.items())
    assert not set(KNOWN_TYPES) & PARAMS_READ_ONLY
    assert set(KNOWN_TYPES.values()) <= set(CTYPES)


@pytest.mark.parametrize(("line", "needle"), BAD)
def test_a_value_the_type_cannot_hold_is_one_line_naming_parameter_value_and_range(line, needle):
    text = BASE + "\n[parameters]\n" + line + "\n"
    with pytest.raises(PlanError, match=re.escape(needle)) as err:
        parse_plan(text=text, source="p.toml")
    name = line.split(" = ")[0]
    assert str(err.value).startswith(f"p.toml:{line_of(text, line)}: parameters.{name}: ")
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("line", ["stabilizer.estimator = 255", "stabilizer.estimator = 0",
                                  "pid_rate.rateFiltEn = -128", "pid_attitude.yaw_kd = 3.4e38",
                                  "powerDist.idleThrust = 4294967295",
                                  "some_group.unknown = 1e39"])  # unknown: the TOC decides
def test_values_the_type_holds_and_unknown_names_pass(line):
    assert parse_plan(text=BASE + "\n[parameters]\n" + line + "\n").parameters


@pytest.mark.parametrize(("line", "needle"), BAD[:1] + BAD[3:4] + BAD[7:8])
def test_plan_check_and_fly_refuse_it_before_connecting(tmp_path, line, needle):
    plan = tmp_path / "p.toml"
    plan.write_text(BASE + "\n[parameters]\n" + line + "\n", encoding="utf-8")
    check = CliRunner().invoke(main, ["plan", "check", str(plan)])
    assert check.exit_code == 2 and needle in check.output, check.output
    assert check.output.count("\n") == 1 and "Traceback" not in check.output
    out = tmp_path / "out"
    # a port nobody answers on: reaching the connect would be a different (link) error
    fly = CliRunner().invoke(main, ["fly", str(plan), "--uri", "udp://127.0.0.1:9",
                                    "--out", str(out), "--timeout", "0.5"])
    assert fly.exit_code == 2 and needle in fly.output, fly.output
    assert fly.output.count("\n") == 1 and not out.exists()


def test_the_documented_error_is_what_the_code_says():
    from groundstation.plan import SHIPPED_PLANS_DIR

    doc = (SHIPPED_PLANS_DIR.parent / "docs" / "flightplans.md").read_text(encoding="utf-8")
    documented = next(ln.strip() for ln in doc.splitlines() if "p.toml:50: parameters." in ln)
    text = BASE + "\n" * (48 - BASE.count("\n")) + "[parameters]\nstabilizer.estimator = 300\n"
    with pytest.raises(PlanError) as err:
        parse_plan(text=text, source="p.toml")
    assert str(err.value) == documented
