"""What the fuzz harness's ``plan`` target (``python -m tests.fuzz.harness --target plan``) found:
plans that escaped as another exception than PlanError, a multi-line or huge message, a
schedule of gigabytes, a check that ran for many seconds, or a plan that loaded but did not
compile. Each is now refused in one line naming key and line (or checked fast); the case is
kept here in its smallest form.
"""

from __future__ import annotations

import random
import re
import time

import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.errors import PlanError
from groundstation.plan import SHIPPED_PLANS_DIR, load_plan, parse_plan
from groundstation.plan.excitation import advance_state, mls_bits, prbs_shift
from tests.plan.conftest import BASE


def _refused(text: str) -> str:
    """The one-line message ``text`` is refused with (and ``plan check`` agrees: exit 2, one
    line)."""
    with pytest.raises(PlanError) as info:
        parse_plan(text=text, source="p.toml")
    msg = str(info.value)
    assert "\n" not in msg and len(msg) < 400 and msg.startswith("p.toml"), msg[:500]
    return msg


@pytest.mark.parametrize("value", ["[" * 3000 + "]" * 3000, "{ a = " * 3000 + "1" + " }" * 3000],
                         ids=["arrays", "inline-tables"])
def test_deep_nesting_is_refused_not_a_recursion_error(value):
    msg = _refused(BASE.replace("hover_thrust = 39000", f"hover_thrust = {value}"))
    assert "nested too deeply" in msg


@pytest.mark.parametrize("key", ["a" + ".a" * 50_000 + " = 1",
                                 "[" + ".".join(["t"] * 50_000) + "]",
                                 "x = { " + ".".join(['"q"'] * 70) + " = 1 }"],
                         ids=["dotted-key", "table-header", "inline-table-key"])
def test_a_key_of_thousands_of_parts_is_refused_before_tomllib_spends_minutes(key):
    """A 100 kB dotted key kept `plan check` for minutes (tomllib's time grows with the square
    of the parts: 10 000 parts 4 s); 64 parts still read, and dotted text in a string is text."""
    msg = _refused(BASE + "\n" + key + "\n")
    assert msg.startswith(f"p.toml:{BASE.count(chr(10)) + 2}: invalid TOML: a dotted key or table")
    assert "more than 64 parts" in msg
    for fine in ("a" + ".a" * 63 + " = 1", 'note = "' + "a." * 1000 + 'a"'):
        assert "64 parts" not in _refused(BASE + "\n" + fine + "\n")  # refused for its key


def test_integer_of_thousands_of_digits_is_invalid_toml_not_a_value_error():
    msg = _refused(BASE.replace("hover_thrust = 39000", "hover_thrust = 1" + "0" * 5000))
    line = BASE[:BASE.index("hover_thrust = 39000")].count("\n") + 1
    # the line named, and no advice meant for Python programmers (review)
    assert msg == (f"p.toml:{line}: invalid TOML: a number of 5001 digits; a plan's numbers "
                   "have a few")


@pytest.mark.parametrize("key", ["hover_thrust", "max_roll_deg", "duration"])
def test_integer_beyond_64_bits_is_refused_not_an_overflow(key):
    text = re.sub(rf"(?m)^{key} = .*$", f"{key} = 1{'0' * 400}", BASE, count=1)
    msg = _refused(text)
    assert "beyond TOML's 64-bit integers" in msg and key in msg


def test_a_parameter_value_beyond_64_bits_is_refused():
    msg = _refused(BASE + "\n[parameters]\npid_attitude.yaw_kd = 1" + "0" * 400 + "\n")
    assert "parameters.pid_attitude.yaw_kd" in msg and "64-bit" in msg


@pytest.mark.parametrize("old, new", [
    ('kind = "takeoff"', "kind = [" + ", ".join(["1"] * 50_000) + "]"),
    ("hover_thrust = 39000", 'hover_thrust = "' + "x" * 100_000 + '"'),
    ("hover_thrust = 39000", "hover_thrust = [" + ", ".join(["1"] * 50_000) + "]"),
    ("[phase.roll]", "roll = [" + ", ".join(["1"] * 50_000) + "]\n[phase.pitch]"),
    ('signal = "prbs"', 'signal = "' + "p" * 100_000 + '"'),
    ("[safety]", '[safety]\n"' + "k" * 5000 + '" = 1'),
], ids=["phase-kind", "string", "array", "table", "choice", "key"])
def test_a_long_value_or_key_is_quoted_short(old, new):
    msg = _refused(BASE.replace(old, new, 1))
    assert "..." in msg


@pytest.mark.parametrize("old, new, where", [
    ("[safety]", '[safety]\n"a\\nb" = 1', "safety.'a\\nb': unknown key 'a\\nb'"),
    ('kind = "takeoff"', "kind = '''multi\nline'''", "'multi\\nline' is not one of"),
    ('kind = "takeoff"', 'kind = "take\\u2028off"', "'take\\u2028off' is not one of"),
    ("[[phase]]", '[parameters]\npid."a\\nb" = 1\n\n[[phase]]', "'pid.a\\nb' is not a firmware"),
    ("[[phase]]", '[altitude_hold]\nvariable = "a.b\\n"\n\n[[phase]]',
     "'a.b\\n' is not a log variable"),
], ids=["key", "choice", "line-separator", "parameter", "log-variable"])
def test_a_line_break_in_a_key_or_value_is_escaped(old, new, where):
    assert where in _refused(BASE.replace(old, new, 1))


def test_a_phase_name_with_a_line_break_given_twice_is_named_on_one_line():
    text = BASE.replace('name = "up"', 'name = "u\\np"').replace('name = "down"', 'name = "u\\np"')
    assert "'u\\np' is already the name of phase[0]" in _refused(text)


def test_thousands_of_long_phases_are_refused_not_gigabytes_of_setpoints():
    """1000 hover phases of an hour each at 100 Hz: 3.6e8 setpoints (14 GB) before the limit."""
    hovers = "".join(f'[[phase]]\nname = "h{k}"\nkind = "hover"\nduration = 3600\n\n'
                     for k in range(1000))
    text = BASE.replace("setpoint_rate_hz = 10", "setpoint_rate_hz = 100").replace(
        '[[phase]]\nname = "excite"', hovers + '[[phase]]\nname = "excite"')
    msg = _refused(text)
    assert msg.startswith("p.toml:28: phase[1].duration: the phases up to this one last 3601 s")
    assert "more than a plan may fly (3600 s" in msg


@pytest.mark.parametrize("value", ["5e-324", "1e-9"])
def test_a_duration_of_no_setpoint_period_is_refused_when_the_plan_loads(value):
    """duration = 5e-324 s is > 0 and within 1e-6 of a whole number of periods (0): it loaded,
    and ``plan check`` then said "schedule phase 'up' does not follow on at tick 0", no key, no
    line (review D)."""
    msg = _refused(BASE.replace('kind = "takeoff"\nduration = 1.0',
                                f'kind = "takeoff"\nduration = {value}'))
    assert re.match(r"p\.toml:21: phase\[0\]\.duration: \S+ s rounds to 0 setpoint periods "
                    r"\(0\.1 s at 10 Hz each\); use 0\.1 s or more$", msg), msg


def test_a_plan_of_exactly_an_hour_loads():
    text = BASE.replace("duration = 3.1", "duration = 3597.1")  # 1 + 3597.1 + 1 s
    assert parse_plan(text=text).duration == pytest.approx(3599.1)
    with pytest.raises(PlanError, match=r"phase\[2\]\.duration: the phases up to this one last"):
        parse_plan(text=text.replace("duration = 1.0\nthrust_start = 36000",
                                     "duration = 2.0\nthrust_start = 36000"))


def test_a_log_chirp_without_a_sweep_is_refused_when_the_plan_loads():
    """It loaded, and compiling it (``plan check``, ``fly``) raised without key or line."""
    text = BASE.replace('signal = "doublet"', 'signal = "chirp"\nf_start_hz = 1.0\n'
                        'f_end_hz = 1.0\nsweep = "log"').replace("width = 0.5\nstart = 0.2\n", "")
    msg = _refused(text)
    assert "phase[1].yaw_rate.f_end_hz" in msg and "no ratio to sweep" in msg
    linear = parse_plan(text=text.replace('sweep = "log"', 'sweep = "linear"'))
    assert np.isfinite(linear.compile().yaw_rate).all()  # a sine: fine


def test_three_24_bit_prbs_check_in_well_under_a_second(tmp_path):
    """``plan check`` prints the lags between PRBS axes; for 24-bit registers that took
    3.3 s and 400 MB per pair (the whole 16.8-million-chip sequence), 10-14 s for three axes."""
    text = re.sub(r"(?m)^register_length = 10\b", "register_length = 24",
                  (SHIPPED_PLANS_DIR / "prbs-3axis.toml").read_text())
    path = tmp_path / "p24.toml"
    path.write_text(text)
    t0 = time.perf_counter()
    result = CliRunner().invoke(main, ["plan", "check", "--json", str(path)])
    assert result.exit_code == 0, result.output
    assert time.perf_counter() - t0 < 3.0
    assert '"lag_ticks"' in result.output
    assert prbs_shift(register_length=24, seed_a=1, seed_b=2) == 16134738  # the old answer
    assert load_plan(path).n_setpoints == 1123


def _brute_shift(n: int, seed_a: int, seed_b: int) -> int:
    a = mls_bits(register_length=n, seed=seed_a)
    ext = np.concatenate([a, a[: n - 1]]).astype(np.int64)
    windows = np.zeros(a.size, dtype=np.int64)
    for i in range(n):
        windows |= ext[i : i + a.size] << i
    return int(np.flatnonzero(windows == seed_b)[0])


@pytest.mark.parametrize("n", [2, 3, 5, 8, 10, 12])
def test_prbs_shift_and_advance_state_agree_with_the_sequence(n):
    rng = random.Random(n)
    top = (1 << n) - 1
    for _ in range(10):
        a, b, d = rng.randint(1, top), rng.randint(1, top), rng.randrange(3 * top)
        assert prbs_shift(register_length=n, seed_a=a, seed_b=b) == _brute_shift(n, a, b)
        bits = mls_bits(register_length=n, seed=a, n_chips=d % top + n)[d % top:]
        state = sum(int(v) << i for i, v in enumerate(bits))
        assert advance_state(register_length=n, seed=a, chips=d) == state
