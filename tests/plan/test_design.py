"""``groundstation plan design``: the next flight's excitation from a model with known poles, fits
and singular values (groundstation/plan/design.py, the rules in docs/flightplans.md)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner

from groundstation.cli import main
from groundstation.errors import PlanError
from groundstation.plan import load_plan, parse_plan
from groundstation.plan.design import (
    ModelFacts,
    choose_seeds,
    design_notes,
    design_plan,
    prbs_timing,
    saturated,
    sv_weakness,
)
from groundstation.plan.excitation import prbs_shift
from groundstation.plan.variants import advance_prbs
from sysid.model import StateSpaceModel
from tests.plan.conftest import BASE
from tests.sysid.flights import known_system, write_flight

DT = 0.02
GYROS = ("gyro.x", "gyro.y", "gyro.z")


def _poles(*taus: float) -> np.ndarray:
    return np.exp(-DT / np.asarray(taus))


def _model(path, *, taus=(0.2, 2.0), outputs=("acc.z", *GYROS), fits=None, sv=None):
    """A model file with real poles of time constants ``taus`` (s) at 50 Hz."""
    n, ell = len(taus), len(outputs)
    prov = {"order": n, "past": 10, "future": 5,
            "singular_values": sv if sv is not None else [10.0] * n + [0.1] * 10}
    if fits is not None:
        prov["fit_percent"] = {"simulation": fits, "1-step": dict.fromkeys(fits, 99.0)}
    StateSpaceModel(A=np.diag(_poles(*taus)), B=np.full((n, 4), 0.01), C=np.ones((ell, n)),
                    dt=DT, input_names=[f"motor.m{i}" for i in range(1, 5)],
                    output_names=list(outputs), provenance=prov).save(path)
    return path


def _facts(*, taus=(0.2, 2.0), fits=None, sv=None) -> ModelFacts:
    return ModelFacts(source="m.json", poles=_poles(*taus), dt=DT, output_names=GYROS,
                      singular_values=None if sv is None else np.asarray(sv, dtype=float),
                      fits=fits or {}, fit_source="given")


def _run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def _amplitudes(plan) -> dict[str, float]:
    return {e.axis: e.amplitude for p in plan.phases for e in p.excitation}


def test_names_from_files_stay_inside_their_comments(tmp_path):
    """A model file named with a line feed and a TOML line: the note names it escaped, on one
    comment line; nothing of the name becomes a key of the plan (it was invalid TOML, and a
    crafted name could have set a key)."""
    model = _model(tmp_path / "m\ninjected = 0\x1b[2J.json",
                   outputs=("acc\nz = 1", *GYROS))
    out = tmp_path / "next.toml"
    res = _run("plan", "design", "--model", model, "--out", out)
    assert res.exit_code == 0, res.output
    text = out.read_text(encoding="utf-8")
    assert "designed from m\\ninjected = 0\\x1b[2J.json by" in text.splitlines()[0]
    assert not any(line.startswith(("injected", "z = 1")) for line in text.splitlines())
    assert _run("plan", "check", out).exit_code == 0
    bad = _model(tmp_path / "m\nx.json", outputs=("acc.z", "gyro.x", "gyro.y", "gyro\nz"))
    res = _run("plan", "design", "--model", bad, "--out", tmp_path / "other.toml")
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "m\\nx.json: the model has no output for the plan's yaw_rate axis" in res.output
    assert "gyro\\nz" in res.output


def test_prbs_timing_follows_the_rule():
    # tau_L = 0.2 s: chip <= 2.78 x 0.2 / 2 = 0.278 s -> 2 ticks at 10 Hz; tau_H = 2 s: period
    # >= 2 pi x 3 x 2 = 37.7 s = 189 chips of 0.2 s -> 8 bits (255 chips = 51 s, fits 102.3 s)
    clock, n, why_clock, why_reg, capped = prbs_timing(poles=_poles(0.2, 2.0), dt=DT,
                                                       rate_hz=10, n_ticks=1023)
    assert (clock, n, capped) == (2, 8, False)
    assert "0.278 s" in why_clock and "37.7 s" in why_reg and "capped" not in why_reg
    # a slowest mode of 20 s asks for 377 s: capped at the longest period the phase holds
    clock, n, _, why_reg, _ = prbs_timing(poles=_poles(0.2, 20.0), dt=DT, rate_hz=10,
                                          n_ticks=1023)
    assert (clock, n) == (2, 9) and "capped" in why_reg and 511 * 2 <= 1023
    # oscillatory modes count by natural frequency: 20 rad/s -> tau_L = 0.05 s -> one tick
    s = complex(-20.0, 0.0) * np.exp(1j * 1.2)
    z = np.exp(np.array([s, s.conjugate()]) * DT)
    assert prbs_timing(poles=z, dt=DT, rate_hz=10, n_ticks=1023)[0] == 1
    # modes beyond the setpoints' Nyquist (here 0.005 s), integrators: nothing to design from
    assert prbs_timing(poles=np.array([_poles(0.005)[0], 1.0]), dt=DT, rate_hz=10,
                       n_ticks=1023) is None


@pytest.mark.parametrize(("fits", "sv", "clock", "why"), [
    # every axis explained well, order well supported: Rivera and Jun's chip, 2.78 x 2 s / 2
    ({g: 95.0 for g in GYROS}, None, 27, "fastest mode below the setpoint Nyquist"),
    # one axis explained poorly: the model may miss fast modes, the flown chip stays
    ({"gyro.x": 95.0, "gyro.y": 95.0, "gyro.z": 60.0}, None, 1, "gyro.z at 60.0 %"),
    ({}, None, 1, "is not known"),                                 # no fits
    ({g: 95.0 for g in GYROS}, [10.0, 2.0] + [1.0] * 10, 1, "singular values"),
])
def test_only_a_model_that_explains_every_axis_lengthens_the_chip(fits, sv, clock, why):
    """A slow model (2 and 20 s) would stretch the thesis' 0.1 s chips to 2.7 s at +-25 deg
    of roll; only a model trusted on every axis may (a low-order model of a flight can miss
    the fast modes: Rivera and Jun's rule wants a low estimate of the time constants)."""
    new = design_plan(load_plan("prbs-3axis"), _facts(taus=(2.0, 20.0), fits=fits, sv=sv),
                      name="next", flown=set()).plan
    assert {e.clock_period for e in new.phases[2].excitation} == {clock}
    assert why in new.text
    # the rule's own chip, as taken or as what the model would have allowed
    assert ("2.78 x 2 s / 2" if clock == 27 else "would allow 2.7 s") in new.text


def test_an_untrusted_model_still_shortens_the_chip():
    base = load_plan("prbs-3axis")
    slow = parse_plan(text=base.text.replace("clock_period = 1", "clock_period = 4"),
                      source="slow.toml")
    assert {e.clock_period for e in slow.phases[2].excitation} == {4}
    # a 0.1 s mode: chip <= 0.139 s -> one tick, though yaw is explained poorly
    new = design_plan(slow, _facts(taus=(0.1, 2.0), fits={"gyro.x": 95.0, "gyro.y": 95.0,
                                                             "gyro.z": 40.0}),
                      name="next", flown=set()).plan
    assert {e.clock_period for e in new.phases[2].excitation} == {1}


def test_designed_plan_passes_check_and_show_explains_it(tmp_path):
    model = _model(tmp_path / "m.json", fits={"gyro.x": 95.0, "gyro.y": 95.0, "gyro.z": 60.0})
    out = tmp_path / "next.toml"
    res = _run("plan", "design", "--model", model, "--out", out)
    assert res.exit_code == 0, res.output
    plan = load_plan(out)
    assert plan.name == "next"
    prbs = [e for e in plan.phases[2].excitation]
    # yaw explained at 60 % only: the chip stays as flown (one tick), and so does the period
    # (the slowest mode asks for 37.7 s = 377 chips of 0.1 s -> 9 bits; flown: 10 bits)
    assert {(e.clock_period, e.register_length) for e in prbs} == {(1, 10)}
    check = _run("plan", "check", out)
    assert check.exit_code == 0 and "warning" not in check.output, check.output
    show = _run("plan", "show", out, "--width", "60")
    assert show.exit_code == 0
    assert "designed from m.json" in show.output
    for key in ("phase[2].roll.seed", "phase[2].yaw_rate.amplitude",
                "phase[2].pitch.seed", "gyro.z at 60.0 %"):
        assert key in show.output
    # the shipped plan's comments and layout are kept: every line is there unchanged, or is a
    # changed value that now says why
    new_lines = out.read_text().splitlines()
    for line in load_plan("prbs-3axis").text.splitlines():
        assert line in new_lines or any(
            n.split("=")[0] == line.split("=")[0] and "# design:" in n for n in new_lines), line


@pytest.mark.parametrize(("fits", "expected"), [
    # yaw explained poorly (60 %, weakness 0.75): x1.75; roll, pitch well (95 %): unchanged
    ({"gyro.x": 95.0, "gyro.y": 95.0, "gyro.z": 60.0}, {"roll": 25, "pitch": 25, "yaw_rate": 87.5}),
    # every axis poorly: doubled at most, and never beyond 0.9 x the vehicle limit (30 deg)
    ({"gyro.x": 0.0, "gyro.y": 40.0, "gyro.z": 10.0}, {"roll": 27, "pitch": 27, "yaw_rate": 100}),
])
def test_axes_with_poor_fits_get_larger_amplitudes_within_the_limits(fits, expected):
    base = load_plan("prbs-3axis")
    new = design_plan(base, _facts(fits=fits), name="next", flown=set()).plan
    assert _amplitudes(new) == pytest.approx(expected)
    limits = {"roll": new.vehicle.max_roll_deg, "pitch": new.vehicle.max_pitch_deg,
              "yaw_rate": new.vehicle.max_yaw_rate_deg_s}
    assert all(a <= limits[k] for k, a in _amplitudes(new).items())
    assert not {e.seed for e in new.phases[2].excitation} & {1, 441, 440}  # --from's own


def test_amplitudes_stay_when_the_flown_motors_were_at_their_limits():
    rng = np.random.default_rng(0)
    motors = np.clip(50000 + 10000 * rng.standard_normal((1000, 4)), 0, 65535)
    at = saturated(motors)  # a plateau at 65535 is a limit; the other extremes are touched once
    assert np.array_equal(at, (motors == 65535).any(axis=1))
    assert at.mean() > 0.05 and not saturated(rng.standard_normal((1000, 4))).any()
    base, poor = load_plan("prbs-3axis"), _facts(fits={g: 20.0 for g in GYROS})
    kept = design_plan(base, poor, name="a", flown=set(), saturation=float(at.mean()))
    assert _amplitudes(kept.plan) == _amplitudes(base)
    assert "no amplitude raised" in kept.notes[3]
    free = design_plan(base, poor, name="b", flown=set(), saturation=0.005)
    assert all(_amplitudes(free.plan)[k] > a for k, a in _amplitudes(base).items())


def test_clipped_motors_leave_the_worst_explained_axis_room():
    """The fits of the first SITL flight (yaw the thesis' weak axis, motors at their limits in
    12.6 % of the excitation): no amplitude is raised, the better-explained axes are lowered by
    1 - 0.5 (w_worst - w), the worst keeps its own."""
    base = load_plan("prbs-3axis")
    fits = {"gyro.x": 74.4, "gyro.y": 71.6, "gyro.z": 27.8}  # weakness 0.39, 0.46, 1
    design = design_plan(base, _facts(fits=fits), name="a", flown=set(), saturation=0.126)
    assert _amplitudes(design.plan) == {"roll": 17.3, "pitch": 18.2, "yaw_rate": 50.0}
    why = {c.path[2]: c.why for c in design.changes if c.path[-1] == "amplitude"}
    assert set(why) == {"roll", "pitch"} and all("gyro.z explained worst" in w
                                                   for w in why.values())
    assert "# design:" in design.plan.text.split("amplitude = 17.3", 1)[1].splitlines()[0]
    # equally weak axes: nothing to shift, the amplitudes stay (see the test above)
    even = design_plan(base, _facts(fits=dict.fromkeys(GYROS, 60.0)), name="b", flown=set(),
                       saturation=0.126)
    assert _amplitudes(even.plan) == _amplitudes(base)


def test_weak_singular_values_excite_every_axis_more():
    base = load_plan("prbs-3axis")
    good = {g: 95.0 for g in GYROS}
    strong = design_plan(base, _facts(fits=good, sv=[10.0, 9.0] + [0.1] * 8), name="a",
                         flown=set()).plan
    weak = design_plan(base, _facts(fits=good, sv=[10.0, 0.2] + [0.1] * 8), name="b",
                       flown=set()).plan
    assert _amplitudes(strong) == _amplitudes(base)
    assert all(_amplitudes(weak)[k] > a for k, a in _amplitudes(base).items())


def test_a_model_not_trusted_never_shortens_the_period():
    """A model fitting 16 % with fast modes only cut the flown 10-bit PRBS to 3 bits (period
    0.7 s, PE order 7) and plan check passed it (first-day review)."""
    base = load_plan("prbs-3axis")
    fast = {"taus": (0.05, 0.1)}
    poor = design_plan(base, _facts(**fast, fits=dict.fromkeys(GYROS, 16.0)), name="a",
                       flown=set())
    assert {e.register_length for e in poor.plan.phases[2].excitation} == {10}
    good = design_plan(base, _facts(**fast, fits=dict.fromkeys(GYROS, 95.0)), name="b",
                       flown=set())
    assert max(e.register_length for e in good.plan.phases[2].excitation) < 10


@pytest.mark.parametrize(("flown", "phase_s", "kept"), [
    # 3-tick chips, 8 bits (76.5 s) in an 80 s phase: 1-tick chips hold no period that long
    # within the phase; they made a 51.1 s period (review of the first fix)
    ((3, 8), 80.0, (3, 8)),
    # 6 bits (6.3 s) of 1-tick chips in 25.2 s: 63 x 0.1 / 0.1 = 63.000000000000014 asked
    # for a 7-bit period (12.7 s) "at least the flown 6.3 s"
    ((1, 6), 25.2, (1, 6)),
])
def test_an_untrusted_model_keeps_the_flown_period_in_whole_ticks(flown, phase_s, kept):
    text = load_plan("prbs-3axis").text.replace("duration = 102.3", f"duration = {phase_s}")
    text = text.replace("register_length = 10", f"register_length = {flown[1]}")
    text = text.replace("clock_period = 1 ", f"clock_period = {flown[0]} ")
    text = text.replace("clock_period = 1\n", f"clock_period = {flown[0]}\n")
    text = text.replace("seed = 441", "seed = 41").replace("seed = 440", "seed = 40")
    plan = parse_plan(text=text, source="flown.toml")
    assert {(e.clock_period, e.register_length) for e in plan.phases[2].excitation} == {flown}
    poor = dict.fromkeys(GYROS, 16.0)
    design = design_plan(plan, _facts(taus=(0.05, 0.1), fits=poor), name="a", flown=set())
    assert {(e.clock_period, e.register_length)
            for e in design.plan.phases[2].excitation} == {kept}
    assert not any("capped by the" in str(c) for c in design.changes)


def test_the_noise_floor_ends_at_the_data_rank():
    """With short horizons the singular values beyond the data's rank are exact zeros; their
    median made any order look supported (sigma_8 / median = 8e14, weakness 0: first-day
    review). The floor is the median of the discarded values up to the rank."""
    weak_with_zeros = [10.0, 0.2] + [0.1] * 8 + [0.0] * 20
    w, note = sv_weakness(_facts(sv=weak_with_zeros))
    assert w == sv_weakness(_facts(sv=weak_with_zeros[:10]))[0] > 0.5, note
    assert "median(discarded) = 2" in note
    w, note = sv_weakness(_facts(sv=[10.0, 9.0] + [1e-16] * 8))  # the order is the rank
    assert w == 1.0 and "no noise floor" in note
    assert sv_weakness(_facts(sv=[10.0, 9.0] + [0.1] * 8))[0] == 0.0


def test_fits_stored_or_implied_by_the_model():
    m = SimpleNamespace(A=np.diag([0.9, 0.5]), dt=DT, output_names=("gyro.x", "gyro.z"),
                        noise_cov=np.diag([4.0, 1.0]),  # what ModelFacts reads of a sysid model
                        provenance={"scaling": {"y_scale": [20.0, 2.0]}})
    facts = ModelFacts.from_model(m, source="m")
    assert facts.fits == pytest.approx({"gyro.x": 90.0, "gyro.z": 50.0})  # 100 (1 - 2/20)
    m.provenance = {"fit_percent": {"simulation": {"gyro.x": 70.0, "gyro.z": float("nan")}}}
    facts = ModelFacts.from_model(m, source="m")
    assert facts.fits == {"gyro.x": 70.0} and "provenance" in facts.fit_source


def test_seeds_differ_from_every_flight_flown(tmp_path):
    base = load_plan("prbs-3axis")
    second = advance_prbs(base, chips=500)
    session = tmp_path / "flown.h5"
    write_flight(session, system=known_system(), seed=1, n=800,
                 metadata={"plan_text": second.text, "plan_name": second.name})
    out = tmp_path / "next.toml"
    res = _run("plan", "design", "--model", _model(tmp_path / "m.json", fits={}), "--out", out,
               "--flown", session)
    assert res.exit_code == 0, res.output
    assert "2 s windows on 1 flown session" in res.output  # the fits were measured on it
    assert "inputs at their limits in 0.0 %" in res.output  # and its motors' headroom
    new = [e for e in load_plan(out).phases[2].excitation]
    flown = {e.seed for p in (base, second) for e in p.phases[2].excitation}
    assert not flown & {e.seed for e in new}


def test_designing_from_a_designed_plan_replaces_its_notes():
    first = design_plan(load_plan("prbs-3axis"), _facts(fits={"gyro.z": 60.0}), name="one",
                        flown=set()).plan
    again = design_plan(first, _facts(fits={g: 95.0 for g in GYROS}), name="two", flown=set())
    header, keys = design_notes(again.plan.text)
    assert len(header) == len(again.notes) and "(from one)" in header[0]
    yaw = dict(keys)["phase[2].yaw_rate.amplitude"]
    assert yaw.startswith("(earlier design) fit gyro.z 60.0 %")  # kept, and says so
    assert _amplitudes(again.plan) == _amplitudes(first)
    assert dict(keys)["phase[2].roll.seed"].endswith(f"was {first.phases[2].excitation[0].seed}")


def test_seed_starts_are_far_from_the_flown_ones():
    flown = {(10, 1), (10, 441), (10, 440)}  # prbs-3axis: starts 0, 341, 682 of 1023
    seeds, apart = choose_seeds(register_length=10, n_axes=3, flown=flown)
    starts = [prbs_shift(register_length=10, seed_a=1, seed_b=s) for s in seeds]
    gaps = [min((a - b) % 1023, (b - a) % 1023) for a in starts for b in (0, 341, 682)]
    assert min(gaps) == apart == 170  # halfway between the flown starts
    assert not {s for _, s in flown} & set(seeds)


def test_inline_tables_and_defaulted_keys_are_written(tmp_path):
    text = BASE.replace(
        '[phase.roll]\nsignal = "prbs"\nregister_length = 5\namplitude = 20.0\nseed = 3\n',
        'roll = { signal = "prbs", register_length = 5, amplitude = 20.0 }  # inline\n')
    text = text.replace("duration = 3.1", "duration = 10.2")
    plan = parse_plan(text=text, source="inline.toml", name="inline")
    design = design_plan(plan, _facts(fits={"gyro.x": 50.0}), name="inline", flown={(5, 1)})
    roll = design.plan.phases[1].excitation[0]
    assert (roll.clock_period, roll.amplitude) == (1, 27.0) and roll.seed != 1
    assert {c.path[-1] for c in design.changes} >= {"amplitude", "seed"}
    # explained well: the amplitude stays, the defaulted chip is lengthened and written
    design = design_plan(plan, _facts(fits={"gyro.x": 95.0}), name="inline", flown={(5, 1)})
    roll = design.plan.phases[1].excitation[0]
    assert (roll.clock_period, roll.amplitude) == (2, 20.0) and roll.seed != 1
    assert {c.path[-1] for c in design.changes} >= {"clock_period", "seed"}


@pytest.mark.parametrize(("case", "needle"), [
    ("missing", "does not exist"),
    ("garbage", "not a readable sysid model"),
    ("nan", "NaN"),
    ("no-gyro", "no output for the plan's roll axis"),
    ("no-vehicle", "vehicle"),
    ("no-prbs", "no PRBS excitation"),
    ("no-plan-text", "holds no plan text"),
])
def test_bad_input_is_one_line_exit_2(tmp_path, case, needle):
    model = tmp_path / "m.json"
    plan, flown = "prbs-3axis", []
    if case == "garbage":
        model = tmp_path / "m.h5"
        model.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(256)) * 4)
    elif case == "nan":
        _model(model).write_text(model.read_text().replace("0.01", "NaN", 1))
    elif case == "no-gyro":
        _model(model, outputs=("acc.x", "acc.y", "acc.z"))
    elif case != "missing":
        _model(model)
    if case == "no-vehicle":
        plan = tmp_path / "p.toml"
        start, end = BASE.index("[vehicle]"), BASE.index("[safety]")
        plan.write_text(BASE[:start] + BASE[end:])
    elif case == "no-prbs":
        plan = "hover-check"
    elif case == "no-plan-text":
        flown = ["--flown", tmp_path / "s.h5"]
        write_flight(tmp_path / "s.h5", system=known_system(), seed=1, n=300)
    res = _run("plan", "design", "--model", model, "--from", plan, "--out",
               tmp_path / "next.toml", *flown)
    assert res.exit_code == 2, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], res.output
    assert not (tmp_path / "next.toml").exists()


def test_a_phase_too_short_for_one_period_is_refused():
    plan = parse_plan(text=BASE.replace("duration = 3.1", "duration = 1.2"), name="short")
    trusted = {g: 95.0 for g in GYROS}  # so its 1.3 s chip is taken: 7 chips do not fit
    with pytest.raises(PlanError, match="lengthen it"):
        design_plan(plan, _facts(taus=(1.0, 2.0), fits=trusted), name="short", flown=set())
    # a model not trusted to lengthen the chip keeps the flown one, which fits
    kept = design_plan(plan, _facts(taus=(1.0, 2.0)), name="short", flown=set())
    assert {e.clock_period for p in kept.plan.phases for e in p.excitation} == {1}
    assert any("as flown" in n for n in kept.notes)


def test_only_the_changed_values_differ_from_the_from_plan():
    base = load_plan("prbs-3axis")
    design = design_plan(base, _facts(fits={"gyro.z": 60.0}), name="next", flown=set())
    lines = design.plan.text.splitlines(keepends=True)[len(design.notes):]
    differ = [b for a, b in zip(base.text.splitlines(keepends=True), lines, strict=True)
              if a != b]
    assert len(differ) == len(design.changes)  # one line per change, every other byte kept
    for ch in design.changes:
        assert any(line.startswith(f"{ch.path[-1]} = ") and line.endswith(f"# design: {ch.why}\n")
                   for line in differ), ch


def test_a_factor_that_changed_a_value_never_reads_one():
    """'x1.00 ...; was 25.0' beside 25.0 -> 24.9 (review): the factor shows its digits."""
    base = load_plan("prbs-3axis")
    fits = {"gyro.x": 50.16, "gyro.y": 20.0, "gyro.z": 20.0}  # roll weakness 0.996, others 1
    design = design_plan(base, _facts(fits=fits), name="a", flown=set(), saturation=0.126)
    (roll,) = [c for c in design.changes if c.path[2:] == ("roll", "amplitude")]
    assert (roll.old, roll.value) == (25.0, 24.9)
    assert "x0.998, rounded down to 0.1" in roll.why and "x1.00" not in roll.why


def test_a_single_axis_prbs_seed_note_names_no_other_axes():
    base = load_plan("roll-only")
    design = design_plan(base, _facts(fits={"gyro.x": 95.0}), name="a", flown=set())
    (seed,) = [c for c in design.changes if c.path[-1] == "seed"]
    assert "the phase's only PRBS axis" in seed.why and "other axes" not in seed.why
    three = design_plan(load_plan("prbs-3axis"), _facts(fits=dict.fromkeys(GYROS, 95.0)),
                        name="b", flown=set())
    assert all(" chips from the other axes" in c.why
               for c in three.changes if c.path[-1] == "seed")


def test_a_session_of_another_plan_is_warned_about(tmp_path):
    """--from roll-only --flown a prbs-3axis session: the motor checks measure the other
    experiment; a warning naming both plans (its seeds are still avoided)."""
    session = tmp_path / "flown.h5"
    other = load_plan("prbs-3axis")
    write_flight(session, system=known_system(), seed=1, n=800,
                 metadata={"plan_text": other.text, "plan_name": other.name})
    model = _model(tmp_path / "m.json", fits={})
    res = _run("plan", "design", "--model", model, "--from", "roll-only", "--out",
               tmp_path / "next.toml", "--flown", session)
    assert res.exit_code == 0, res.output
    assert (f"warning: {session} flew plan 'prbs-3axis', not 'roll-only' (--from)"
            in res.stderr), res.stderr
    same = _run("plan", "design", "--model", model, "--from", "prbs-3axis", "--out",
                tmp_path / "same.toml", "--flown", session)
    assert same.exit_code == 0 and "warning" not in same.stderr, same.stderr
