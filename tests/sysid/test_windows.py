"""Default windows (excitation, else airborne segments), per-session and phase-relative
windows, the logged rate as default grid, and anti-aliased decimation."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from click.testing import CliRunner

from sysid.cli import main
from sysid.errors import DataError, ParameterError
from sysid.session_io import (
    PhaseRelative,
    load_experiments,
    load_session,
    load_sessions,
    parse_window,
)
from tests.sysid.flights import (
    SessionWriter,
    known_system,
    log_block_spec,
    standard_streams,
    write_flight,
)

# the session writer as flights.py imports it (its package moves in the layout change)
from tests.sysid.systems import pole_error

# an imported log: ground, airborne, ground, airborne, ground (host seconds)
AIRBORNE = [(0.0, "ground-0", "ground"), (4.0, "airborne-1", "airborne"),
            (22.0, "ground-1", "ground"), (26.0, "airborne-2", "airborne"),
            (46.0, "ground-2", "ground")]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("win")
    system = known_system()
    return {"recorded": write_flight(d / "rec.h5", system=system, seed=1).path,
            "imported": write_flight(d / "imp.h5", system=system, seed=2,
                                     phases=AIRBORNE).path,
            "imported2": write_flight(d / "imp2.h5", system=system, seed=3,
                                      phases=AIRBORNE).path,
            "log": write_flight(d / "log.h5", system=system, seed=4,
                                phases=[(0.0, "log", "log")]).path}


def test_parse_window_forms() -> None:
    assert parse_window("auto") == "auto" and parse_window("all") is None
    assert parse_window("hover") == "hover" and parse_window("1.5:4") == (1.5, 4.0)
    assert parse_window("airborne-1@0.5:3") == PhaseRelative("airborne-1", 0.5, 3.0)
    assert parse_window("airborne-1@2:") == PhaseRelative("airborne-1", 2.0, None)
    for bad in ("a:b", "x@1", "@1:2", "3:1", "p@2:1", "1:inf"):
        with pytest.raises(ParameterError):
            parse_window(bad)


def test_auto_is_the_excitation_else_each_airborne_segment(files) -> None:
    rec = load_experiments(files["recorded"], dt=0.02)
    assert len(rec) == 1 and rec[0].n_samples == load_session(files["recorded"]).n_samples
    imp = load_experiments(files["imported"], dt=0.02)
    assert [e.source.rsplit("#", 1)[1] for e in imp] == ["airborne-1", "airborne-2"]
    # 18 s and 20 s on a 0.02 s grid (phases are [start, end); a sample or two of edge)
    assert abs(imp[0].n_samples - 900) <= 2 and abs(imp[1].n_samples - 1000) <= 2
    one = load_session(files["imported"], window="airborne-2")
    np.testing.assert_allclose(imp[1].u, one.u)
    # the kind: each segment too, never the ground between them (it spanned 4-46 s)
    kind = load_experiments(files["imported"], window="airborne", dt=0.02)
    assert [e.n_samples for e in kind] == [e.n_samples for e in imp]
    with pytest.raises(DataError, match=r"no excitation or airborne-N phase .*\['log'\]"):
        load_experiments(files["log"])
    with pytest.raises(DataError, match="selects 2 experiments"):
        load_session(files["imported"], window="auto")


def test_auto_takes_each_excitation_phase_as_its_own_experiment(tmp_path) -> None:
    """A flight with a PRBS, a hover and a chirp (roll-only, pitch-only, yaw-only): two
    experiments, so the held-out 30 % of each validates (joined, the held-out part was the
    chirp's end alone); the kind as a window still joins them, hover included."""
    path = write_flight(tmp_path / "two.h5", system=known_system(), seed=5, phases=[
        (0.0, "takeoff", "takeoff"), (5.0, "prbs", "excitation"), (25.0, "rest", "hover"),
        (27.0, "chirp", "excitation"), (37.0, "land", "landing")]).path
    exps = load_experiments(path, dt=0.02)
    assert [e.source.rsplit("#", 1)[1] for e in exps] == ["prbs", "chirp"]
    assert [round(e.n_samples * 0.02) for e in exps] == [20, 10]
    joined = load_session(path, window="excitation", dt=0.02)
    assert round(joined.n_samples * 0.02) == 32  # the 2 s hover between them included
    same = write_flight(tmp_path / "same.h5", system=known_system(), seed=5, phases=[
        (0.0, "takeoff", "takeoff"), (5.0, "excitation", "excitation"),
        (25.0, "excitation", "excitation"), (37.0, "land", "landing")]).path
    assert [e.source.rsplit("#", 1)[1] for e in load_experiments(same, dt=0.02)] == [
        "excitation", "excitation-2"]
    taken = write_flight(tmp_path / "taken.h5", system=known_system(), seed=5, phases=[
        (0.0, "takeoff", "takeoff"), (5.0, "prbs", "excitation"), (15.0, "prbs", "excitation"),
        (25.0, "prbs-2", "excitation"), (37.0, "land", "landing")]).path
    assert [e.source.rsplit("#", 1)[1] for e in load_experiments(taken, dt=0.02)] == [
        "prbs", "prbs-2", "prbs-2-2"]  # every label its own


def test_a_grid_of_gigabytes_is_refused_before_it_is_built(files, monkeypatch) -> None:
    """The 1000x rule bounds the grid against the log's rate, not its length: a long log could
    still ask for gigabytes (the cap: 2**28 values, 2 GiB; lowered here to the test log's)."""
    import sysid.session_io

    monkeypatch.setattr(sysid.session_io, "_MAX_GRID_VALUES", 100_000)
    with pytest.raises(ParameterError, match=r"dt=0\.001 s puts 5(\.\d+)?e\+04 samples of 10 "
                                             r"channels on the grid .*; pass dt >= 0\.005"):
        load_experiments(files["recorded"], dt=0.001)
    assert load_experiments(files["recorded"], dt=0.02)  # the logged rate: far below the cap


def test_a_grid_period_given_in_milliseconds_is_refused_as_such(files) -> None:
    """`--dt 20` (meant: 20 ms) on a 50 Hz log left 6 samples of a 102 s flight, refused
    downstream as too few for the horizons ("... looks transposed") or for choosing them
    ("give horizons ..."): the cause, dt in seconds, went unsaid."""
    with pytest.raises(ParameterError, match=r"dt=20 s is 1000x the logged period 0\.02 s "
                                             r"\(50 Hz\); dt is in seconds: pass dt <= 2 "):
        load_experiments(files["recorded"], dt=20.0)
    assert load_experiments(files["recorded"], dt=2.0)[0].n_samples == 20  # 100x: still taken


def test_a_window_outside_the_data_says_where_the_data_are(files) -> None:
    """A T0:T1 past the log's end (or given in ms) said only "pick another window"."""
    with pytest.raises(DataError, match=r"window 500:600 .* every channel has data \(session "
                                        r"seconds 0\.5 to 50\.5\); pick a window within them"):
        load_experiments(files["recorded"], window=(500.0, 600.0))


def test_a_phase_relative_window_stays_within_its_phase(files, caplog) -> None:
    """``airborne-1@10:30`` (the phase lasts 18 s) took the ground and the next segment's
    take-off after it, silently; a negative T0 took the ground before it."""
    with caplog.at_level(logging.WARNING, logger="sysid.session_io"):
        cut = load_session(files["imported"], window=PhaseRelative("airborne-1", 10.0, 30.0))
    assert cut.n_samples == load_session(
        files["imported"], window=PhaseRelative("airborne-1", 10.0)).n_samples
    assert any("ends 12.00 s after the phase 'airborne-1' (it lasts 18.00 s): cut at its end"
               in r.getMessage() for r in caplog.records)
    with pytest.raises(ParameterError, match=r"T0 is seconds from the phase start, at least 0; "
                                             r".* \(the phase starts at 4\.00 s\)"):
        load_session(files["imported"], window=PhaseRelative("airborne-1", -1.0, 5.0))
    with pytest.raises(DataError, match=r"airborne-1@20: starts after the phase 'airborne-1' "
                                        r"ends \(it lasts 18\.00 s\); give T0 < 18\.00"):
        load_session(files["imported"], window=PhaseRelative("airborne-1", 20.0))
    # a kind that several phases have: the first one's own span, not to the last one's end
    kind = load_session(files["imported"], window=PhaseRelative("airborne", 10.0))
    assert kind.n_samples == load_session(
        files["imported"], window=PhaseRelative("airborne-1", 10.0)).n_samples


def test_phase_relative_and_per_session_windows(files) -> None:
    rel = load_session(files["imported"], window=PhaseRelative("airborne-2", 2.0, 12.0))
    absolute = load_session(files["imported"], window=(28.0, 38.0))
    np.testing.assert_allclose(rel.y, absolute.y)
    to_end = load_session(files["imported"], window=PhaseRelative("airborne-2", 10.0))
    assert abs(to_end.n_samples - 500) <= 2
    groups = load_sessions([files["imported"], files["recorded"]],
                           windows={"imp.h5": PhaseRelative("airborne-1", 0.0, 5.0)})
    assert [len(g) for g in groups] == [1, 1]
    assert abs(groups[0][0].n_samples - 250) <= 2 and groups[1][0].n_samples == 2000
    with pytest.raises(ParameterError, match="no such session"):
        load_sessions([files["imported"]], windows={"other.h5": None})


def test_grid_is_the_logged_rate_and_faster_streams_are_anti_aliased(tmp_path, caplog):
    """A 40 Hz tone logged at 100 Hz held onto a 50 Hz grid aliases to 10 Hz at full size;
    the anti-alias filter removes it and keeps a 1 Hz signal."""
    path = tmp_path / "fast.h5"
    n = 3000
    t = np.arange(n) * 0.01
    slow = np.sin(2 * np.pi * 1.0 * t)
    tone = np.sin(2 * np.pi * 40.0 * t)
    specs = [log_block_spec(name="cmd", variables=[("ctl.u", "float")], period_s=0.01),
             log_block_spec(name="out", variables=[("ctl.y", "float")], period_s=0.01)]
    with SessionWriter(path, streams=[*specs, *standard_streams()], metadata={}) as w:
        w.phase(t=0.0, phase_id=0, name="excitation", kind="excitation")
        for spec, values in (("cmd", slow + tone), ("out", np.cos(2 * np.pi * 1.3 * t))):
            w.extend(spec, [(float(t[k]) + 0.002, 1000 + 10 * k, float(values[k]))
                            for k in range(n)])
        w.close(duration_s=float(t[-1]) + 0.01)
    native = load_session(path, inputs=["cmd"], outputs=["out"], dt=None, detrend=None)
    assert native.dt == pytest.approx(0.01) and native.n_samples >= n - 2
    with caplog.at_level(logging.WARNING, logger="sysid.session_io"):
        fifty = load_session(path, inputs=["cmd"], outputs=["out"], dt=0.02, detrend=None)
    assert any("anti-alias" in r.getMessage() and "100 Hz" in r.getMessage()
               for r in caplog.records), caplog.text
    u = fifty.u[100:-100, 0]  # away from the filter's edge transients
    spec = np.abs(np.fft.rfft(u * np.hanning(u.size))) / (u.size / 4)
    freqs = np.fft.rfftfreq(u.size, 0.02)
    at = {f: spec[np.argmin(np.abs(freqs - f))] for f in (1.0, 10.0)}
    assert at[1.0] > 0.9 and at[10.0] < 0.01, at  # held without the filter: ~1.0 at 10 Hz


def test_identify_with_no_knobs_on_imported_airborne_segments(files, tmp_path) -> None:
    """No horizons nor order given: chosen on held-out data of the airborne segments."""
    out = tmp_path / "m.h5"
    res = CliRunner().invoke(main, ["identify", str(files["imported"]), "--validate",
                                    str(files["imported2"]), "--out", str(out), "--json"])
    assert res.exit_code == 0, res.output
    rep = json.loads(res.stdout)
    sel = rep["selection"]
    assert "last 30 %" in sel["rule"] and len(rep["experiments"]) == 2
    assert (rep["past"], rep["future"], rep["order"]) == (
        sel["chosen"]["past"], sel["chosen"]["future"], sel["chosen"]["order"])
    assert len(sel["grid"]["pasts"]) > 1 and len(sel["grid"]["orders"]) > 1
    # The simulated vehicle has order 4. The held-out segments (unequal lengths) measure the
    # score to 0.12 points and rank order 6 0.17 above order 4, so 4-6 are sound choices
    # (noise-free truth: 99.03 / 98.99 / 98.79 % for orders 4 / 5 / 6); the vehicle's four
    # poles are in the model whichever is chosen.
    assert 4 <= rep["order"] <= 6
    poles = np.array([complex(*p) for p in sel["chosen"]["poles"]])
    assert pole_error(np.linalg.eigvals(known_system().A), poles) < 0.03
    assert sel["candidates"][0]["score_percent"] >= sel["candidates"][-1]["score_percent"]
    assert rep["stable"] and sel["chosen"]["score_percent"] > 50
    assert rep["dt_s"] == pytest.approx(0.02)  # the logged rate
    # one rule: the rows are what `sysid compare` prints by default (they used the
    # selection's score window, 1.07 s beside compare's 2 s: first-day review)
    assert [m["mode"] for m in rep["validation"]] == [
        "validation: simulation", "validation: 1-step prediction"]  # no pole near |z| = 1
    assert rep["simulation_window_s"] is None
    assert min(rep["validation"][1]["fit_percent"].values()) > 50
    text = CliRunner().invoke(main, ["compare", str(out), str(files["imported2"]),
                                     "--horizon", "1"])
    assert text.exit_code == 0 and "imp2.h5#airborne-2" in text.stdout, text.output


def test_a_session_without_default_phases_is_refused_in_each_commands_words(files,
                                                                            tmp_path) -> None:
    """A log with only a "log" phase: each command refuses the default window saying what it
    would have done (compare said "no ... phase to identify from", and compare identifies
    nothing); the phases and the --window forms follow."""
    model = tmp_path / "m.h5"
    res = CliRunner().invoke(main, ["identify", str(files["recorded"]), "--order", "4",
                                    "--past", "10", "--future", "5", "--out", str(model)])
    assert res.exit_code == 0, res.output
    log = str(files["log"])
    for args, verb in ((["identify", log, "--order", "4"], "identify from"),
                       (["order", log], "choose the order from"),
                       (["compare", str(model), log], "compare the model on"),
                       (["resid", str(model), log], "analyse the residuals on"),
                       (["identify", str(files["recorded"]), "--order", "4", "--past", "10",
                         "--future", "5", "--validate", log], "validate the model on")):
        res = CliRunner().invoke(main, args)
        err = " ".join(res.stderr.split())
        assert res.exit_code == 2 and f"no excitation or airborne-N phase to {verb} " \
            "(phases are ['log']); pass a window" in err, (args, res.output)
    with pytest.raises(DataError, match="phase to compare the model on"):
        load_experiments(files["log"], verb="compare the model on")


def _log_session(path, *, phases: list[tuple[float, str, str]], n: int = 2048):
    """An imported-like session written by the project's writer: two 100 Hz streams whose
    host time is their firmware time (as ``groundstation import`` writes them), ``phases``
    ``(host time, name, kind)``; returns the sample times."""
    t = 1.0 + 0.01 * np.arange(n)
    specs = [log_block_spec(name="cmd", variables=[("ctl.u", "float")], period_s=0.01),
             log_block_spec(name="out", variables=[("ctl.y", "float")], period_s=0.01)]
    rng = np.random.default_rng(5)
    with SessionWriter(path, streams=[*specs, *standard_streams()], metadata={}) as w:
        for pid, (start, name, kind) in enumerate(phases):
            w.phase(t=start, phase_id=pid, name=name, kind=kind)
        for spec in ("cmd", "out"):
            values = rng.standard_normal(n)
            w.extend(spec, [(float(t[k]), round(1000 * t[k]), float(values[k]))
                            for k in range(n)])
        w.close(duration_s=float(t[-1] - t[0]))
    return t


def test_a_window_to_the_end_of_the_log_keeps_its_last_sample(tmp_path) -> None:
    """An imported log without airborne segments has one phase, ``log``, over the whole log
    (docs/session-format.md). Phases are [start, end) and the last one ends at the last
    sample, so ``--window log`` dropped that sample (2048 -> 2047) where ``all`` kept it. A
    window that reaches the end of the session now runs to its last sample; a phase that
    another follows still ends before the next one's first instant."""
    kw = {"inputs": ["cmd"], "outputs": ["out"], "dt": None, "detrend": None}
    path = tmp_path / "log.h5"
    t = _log_session(path, phases=[(1.0, "log", "imported")])
    whole = load_experiments(path, window=None, **kw)[0]
    assert whole.n_samples == 2048
    log = load_experiments(path, window="log", **kw)[0]
    assert log.n_samples == 2048
    np.testing.assert_array_equal(log.y, whole.y)
    rest = load_experiments(path, window=PhaseRelative("log", 10.0), **kw)[0]
    assert rest.n_samples == 2048 - 1000  # from 10 s into the phase to the end, last included
    assert load_experiments(path, window=(float(t[0]), float(t[-1]) + 5.0), **kw)[0].n_samples \
        == 2048
    # [start, end) between phases: the sample at the boundary is the next phase's only
    split = tmp_path / "split.h5"
    t = _log_session(split, phases=[(1.0, "ground-0", "ground"),
                                    (float(t[1000]), "airborne-1", "airborne")])
    ground = load_experiments(split, window="ground-0", **kw)[0]
    air = load_experiments(split, window="airborne-1", **kw)[0]
    assert (ground.n_samples, air.n_samples) == (1000, 1048)
    both = load_experiments(split, window=None, **kw)[0]
    np.testing.assert_array_equal(np.vstack([ground.y, air.y]), both.y)
    inner = load_experiments(split, window=(float(t[10]), float(t[20])), **kw)[0]
    assert inner.n_samples == 10  # T0:T1 inside the log: [T0, T1)


def test_two_windows_for_one_session_by_path_and_by_name_are_refused(tmp_path) -> None:
    """``--window DIR/X.h5=prbs --window X.h5=settle``: the path's won, the name's was ignored
    in silence (review)."""
    path = write_flight(tmp_path / "x.h5", system=known_system(), seed=3, n=600).path
    with pytest.raises(ParameterError, match=r"two windows for session .*x\.h5: one given for "
                                             r"its path, one for its name 'x\.h5'"):
        load_sessions([str(path)], inputs=["motor.m1"], outputs=["gyro.x"],
                      windows={str(path): "excitation", "x.h5": None})


def _edited(src, dst, stream, field, change):
    import shutil

    import h5py

    shutil.copy(src, dst)
    with h5py.File(dst, "a") as f:
        data = f[f"{stream}/data"][()]
        data[field] = change(data[field])
        f[f"{stream}/data"][...] = data
    return dst


def test_firmware_times_that_do_not_advance_are_called_damaged(files, tmp_path) -> None:
    """All of gyro's fw_time_ms equal: the message was "dt=0.02 s is longer than the -0.02 s
    where every channel has data; pass a smaller dt", which no dt answers."""
    path = _edited(files["recorded"], tmp_path / "still.h5", "gyro", "fw_time_ms",
                   lambda v: np.full_like(v, 1234))
    with pytest.raises(DataError, match=r"still\.h5: the firmware time \(fw_time_ms\) of log "
                                        r"stream\(s\) \['gyro'\] does not advance over its "
                                        r"rows; the file's time stamps are damaged"):
        load_experiments(path)


def test_a_value_that_is_no_number_names_the_file(files, tmp_path) -> None:
    """A NaN in gyro.x: "stream 'gyro.x': non-finite value at sample 0" named no file (which of
    the sessions given to sweep or identify?) (review D)."""
    path = _edited(files["recorded"], tmp_path / "nan.h5", "gyro", "x",
                   lambda v: np.where(np.arange(len(v)) == 3, np.nan, v))
    with pytest.raises(DataError, match=r"nan\.h5: stream 'gyro\.x': non-finite value at "
                                        r"sample 3; remove or repair it"):
        load_experiments(path, outputs=["gyro.x"])


def test_a_damaged_host_time_does_not_size_the_grid(files, tmp_path) -> None:
    """One host_time of 1.7e308 (the grid is on firmware time) refused the session with
    "puts inf samples ... pass dt >= inf" and four RuntimeWarnings."""
    path = _edited(files["recorded"], tmp_path / "far.h5", "acc", "host_time",
                   lambda v: np.where(np.arange(len(v)) == len(v) - 1, 1.7e308, v))
    assert load_experiments(path)[0].n_samples == load_experiments(files["recorded"])[0].n_samples


def test_a_logged_period_the_grid_cannot_take_names_the_file(files, tmp_path) -> None:
    """compare/resid pass the model's dt: the refusal named no file (which of the sessions?)."""
    import shutil

    import h5py

    path = tmp_path / "slow.h5"
    shutil.copy(files["recorded"], path)
    with h5py.File(path, "a") as f:
        for s in ("motors", "acc", "gyro"):
            f[s].attrs["period_s"] = 9e5
    with pytest.raises(ParameterError, match=r"slow\.h5: dt=0\.02 s is 4\.5e\+07x finer than "
                                             r"the logged period 900000 s"):
        load_experiments(path, dt=0.02)


def test_many_phases_of_one_name_are_labelled_in_linear_time() -> None:
    """40 000 excitation phases named `prbs` (a 2 MB file) hung every sysid command: each label
    searched prbs-2, prbs-3, ... from the start."""
    from sysid.session_io import unique_name

    class Counted(set):
        lookups = 0

        def __contains__(self, item) -> bool:
            Counted.lookups += 1
            return super().__contains__(item)

    taken, tried = Counted(), {}
    for _ in range(2000):
        taken.add(unique_name("prbs", taken, tried=tried))
    assert sorted(taken) == sorted(["prbs", *(f"prbs-{k}" for k in range(2, 2001))])
    assert Counted.lookups < 3 * 2000  # was 2 million
    assert unique_name("hover", {"hover", "hover-2"}) == "hover-3"  # without tried, as before


def test_a_log_stream_without_firmware_time_is_one_line(files, tmp_path) -> None:
    """sysid places samples at their firmware time: a log stream without `fw_time_ms` (which
    the session format allows, and `info` and `export` read) was a TypeError traceback."""
    import shutil

    import h5py

    path = tmp_path / "untimed.h5"
    shutil.copy(files["recorded"], path)
    with h5py.File(path, "a") as f:
        data = f["gyro/data"][()]
        keep = [n for n in data.dtype.names if n != "fw_time_ms"]
        del f["gyro/data"]
        f["gyro"].create_dataset("data", data=np.array(data[keep].tolist(), dtype=[
            (n, data.dtype.fields[n][0]) for n in keep]))
    res = CliRunner().invoke(main, ["identify", str(path), "--order", "2", "--past", "5",
                                    "--future", "5"])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert ("untimed.h5: log stream(s) ['gyro'] have no firmware time (field 'fw_time_ms')"
            in res.output)


def _no_search(*args, **kwargs):
    raise AssertionError("the search ran")


def test_a_sessions_window_too_short_to_score_is_refused_before_the_search(files, monkeypatch
                                                                            ) -> None:
    """A 15-sample window on the validating session ran the whole selection (the score's
    tolerance fell back, a warning only); refused in one line naming the session and the
    window, before any search: identify's held-out session, sweep's --validate."""
    monkeypatch.setattr("sysid.cli_identify.choose", _no_search)
    monkeypatch.setattr("sysid.cli_sweep.choose", _no_search)
    rec, imp = str(files["recorded"]), str(files["imported"])
    for args in (["identify", rec, imp], ["sweep", rec, "--validate", imp]):
        res = CliRunner().invoke(main, [*args, "--window", "imp.h5=airborne-1@0:0.3"])
        err = " ".join(res.stderr.split())
        assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1, res.output
        assert err.startswith("error: imp.h5: --window imp.h5=airborne-1@0:0.3 holds 15 "
                              "samples (0.3 s at dt 0.02 s), fewer than the 20"), err
        assert "give imp.h5 a window of 0.4 s at least" in err


def test_a_per_session_window_may_name_a_validate_session(files, monkeypatch, caplog) -> None:
    """`sweep A --validate V --window V=...` said "no such session among ['A']": the
    --validate sessions are the command's too (identify's as well); a name that is neither
    is still refused."""
    rec, imp = str(files["recorded"]), str(files["imported"])
    seen = {}

    def record(groups, *, validation, **kwargs):
        seen["validation"] = [(d.source, d.n_samples) for d in validation]
        raise DataError("stop here")

    monkeypatch.setattr("sysid.cli_sweep.choose", record)
    res = CliRunner().invoke(main, ["sweep", rec, "--validate", imp, "--window",
                                    "imp.h5=airborne-1@0:5"])
    assert "stop here" in res.stderr and [n for _, n in seen["validation"]] == [250], \
        res.output
    res = CliRunner().invoke(main, ["identify", rec, "--order", "4", "--past", "10", "--future",
                                    "5", "--validate", imp, "--window", "imp.h5=airborne-1@0:0.3"])
    assert res.exit_code == 0, res.output  # the window reached the validation session:
    assert "validation not scored: imp.h5 has 15 samples in its window" in caplog.text
    for args in (["sweep", rec, "--validate", imp], ["identify", rec, "--validate", imp]):
        res = CliRunner().invoke(main, [*args, "--window", "other.h5=all"])
        assert res.exit_code == 2 and "window for ['other.h5']: no such session among " \
            f"[{rec!r}, {imp!r}]" in " ".join(res.stderr.split()), res.output
