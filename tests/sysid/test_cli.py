"""The sysid command line on session files of a known closed-loop system."""

from __future__ import annotations

import json
import re
import sys

import numpy as np
import pytest
from click.testing import CliRunner

import sysid
from sysid.cli import main, parse_grid
from sysid.errors import ParameterError
from sysid.validate import fit_percent
from tests.sysid.flights import PWM_MID, held, known_system, write_flight
from tests.sysid.systems import pole_error
from tests.sysid.test_session_io import K0, N_EXC

FAST = ["--order", "4", "--past", "20", "--future", "10"]


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli")
    system = known_system()
    return [write_flight(d / f"f{i}.h5", system=system, seed=10 + i) for i in range(2)]


def run(*args: str) -> object:
    return CliRunner().invoke(main, [str(a) for a in args])


def test_identify_recovers_the_closed_loop_poles(flights, tmp_path) -> None:
    out = tmp_path / "m.h5"
    res = run("identify", flights[0].path, *FAST, "--out", out, "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    poles = np.array([p["re"] + 1j * p["im"] for p in report["poles"]])
    truth = flights[0].system.poles()
    assert pole_error(truth, poles) < 0.03
    assert report["stable"] and report["predictor_stable"]
    assert min(report["fit_percent"]["1-step"].values()) > 50
    model = sysid.load_model(out)
    assert pole_error(truth, model.poles()) < 0.03
    assert model.input_names[0] == "motor.m1" and model.output_units[-1] == "deg/s"
    assert model.provenance["sources"] == [str(flights[0].path)]


def test_identify_several_sessions_makes_one_model(flights, tmp_path) -> None:
    out = tmp_path / "both.json"
    res = run("identify", *(f.path for f in flights), *FAST, "--out", out)
    assert res.exit_code == 0, res.output
    assert "pole" in res.stdout and "simulation" in res.stdout
    model = sysid.load_model(out)
    assert model.provenance["n_flights"] == 2
    assert pole_error(flights[0].system.poles(), model.poles()) < 0.03


def test_compare_with_the_true_model_reaches_the_noise_limit(flights, tmp_path) -> None:
    """The true system, in the session's units, fits as well as its noise-free output does."""
    f = flights[1]
    true_path = tmp_path / "true.h5"
    f.system.save(true_path)
    res = run("compare", true_path, f.path, "--window-s", "10", "--horizon", "1", "--json")
    assert res.exit_code == 0, res.output
    modes = {m["mode"]: m for m in json.loads(res.stdout)["modes"]}
    sim = modes["simulation, 10 s windows"]["sessions"][0]["fit_percent"]
    # noise-free response to the input as logged (dropped packets held), excitation samples
    n = len(f.values["motors"])
    u_logged = held(f.values["motors"], f.dropped["motors"], np.arange(n)) - PWM_MID
    y_ref = f.system.simulate(u_logged)[K0:K0 + N_EXC]
    y = np.hstack([held(f.values[s], f.dropped[s], K0 + np.arange(N_EXC)) for s in ("acc", "gyro")])
    ideal = fit_percent(y - y.mean(0), y_ref - y_ref.mean(0))
    got = np.array(list(sim.values()))
    assert np.all(np.abs(got - ideal) < 2.0), (got, ideal)
    # With the true K the one-step error is the innovation (std 0.05) unless packets were
    # dropped (a held sample is an error of the signal's size): perfect log -> near 100 %.
    clean = write_flight(tmp_path / "nodrop.h5", system=known_system(), seed=3, n_drop=0)
    res = run("compare", true_path, clean.path, "--horizon", "1", "--json")
    one_step = np.array(list(json.loads(res.stdout)["modes"][0]["overall"].values()))
    assert np.all(one_step > 97.0), one_step


def test_compare_table_per_session(flights, tmp_path) -> None:
    path = tmp_path / "true.h5"
    flights[0].system.save(path)
    res = run("compare", path, flights[0].path, flights[1].path)
    assert res.exit_code == 0, res.output
    assert "f0.h5" in res.stdout and "f1.h5" in res.stdout and "all" in res.stdout


def test_order_suggests_the_true_order(flights) -> None:
    res = run("order", flights[0].path, "--past", "20", "--future", "10", "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["suggested_order"] == 4
    sv = np.array(report["singular_values"])
    assert np.all(np.diff(sv) <= 0)


def test_order_suggests_a_command_with_the_options_given(flights) -> None:
    """The suggested `identify` reads the same data: the session options given (not a
    reminder to repeat them), none when all are the defaults."""
    res = run("order", flights[0].path, "--past", "20", "--future", "10", "--outputs", "gyro",
              "--window", "excitation", "--detrend", "linear")
    assert res.exit_code == 0, res.output
    line = " ".join(res.stdout.split())
    assert (f"to identify with it: sysid identify {flights[0].path} --method iem --past 20 "
            "--future 10 --order 4 --outputs gyro --window excitation --detrend linear; "
            "without") in line, line
    plain = " ".join(run("order", flights[0].path, "--past", "20", "--future", "10").stdout
                     .split())
    assert "--order 4; without" in plain and "same channel options" not in plain


def test_compare_with_the_arguments_swapped_says_to_swap_them(flights, tmp_path) -> None:
    model = tmp_path / "true.h5"
    flights[0].system.save(model)
    for command in ("compare", "resid"):
        res = run(command, flights[0].path, model)
        assert res.exit_code == 2, res.output
        assert res.stderr.strip() == (
            f"error: {flights[0].path} is a flight session and {model} a model: the model comes "
            f"first, swap them: sysid {command} {model} {flights[0].path}")


def test_a_flight_log_passed_as_a_session_says_to_import_it(tmp_path) -> None:
    """A uSD-card log or a cfclient CSV is no session: one line names what it is and the
    command that makes a session of it."""
    usd = tmp_path / "log00"
    usd.write_bytes(b"\xbc\x02\x00\x02\x00\xff\xffrest of a deck log")
    csv = tmp_path / "stab-20260101T10-00-00.csv"
    csv.write_text("Timestamp,stabilizer.roll\n1000,0.5\n")
    for path, what in ((usd, "Crazyflie uSD-card deck log"), (csv, "cfclient log CSV")):
        res = run("identify", path)
        assert res.exit_code == 2, res.output
        assert res.stderr.strip() == (
            f"error: {path}: not an HDF5 file, so not a session file: it is a {what}; make a "
            f"session of it with `groundstation import {path} --out DIR`")


def test_sweep_help_names_both_range_forms() -> None:
    text = " ".join(run("sweep", "--help").stdout.split())
    for option in ("--pasts", "--futures", "--orders"):
        assert f"{option} TEXT START:STOP (every value), START:STOP:STEP or a,b,c" in text


def test_sweep_picks_the_true_order(flights) -> None:
    res = run("sweep", flights[0].path, "--pasts", "15,20", "--futures", "10",
              "--orders", "2:6:2", "--horizon", "1", "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["n_models"] == 6 and report["best"]["order"] == 4
    tops = [r["mean_fit_percent"] for r in report["top"]]
    assert tops == sorted(tops, reverse=True)


def test_sweep_saves_the_selected_model(flights, tmp_path) -> None:
    out = tmp_path / "best.h5"
    res = run("sweep", flights[0].path, "--pasts", "10,20", "--futures", "10",
              "--orders", "3,4", "--out", out, "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    best = report["best"]
    assert report["model"] == str(out) and "last 30 %" in report["rule"]
    model = sysid.load_model(out)
    assert (model.provenance["past"], model.provenance["future"], model.A.shape[0]) == (
        best["past"], best["future"], best["order"])
    # identified again on the whole session, not on the 70 % that took part in the sweep
    assert model.provenance["n_samples"] == [N_EXC]
    again = run("sweep", flights[0].path, "--pasts", "10", "--futures", "10", "--orders", "4",
                "--out", out)
    assert again.exit_code == 2 and "already exists" in again.stderr


def _refusing_all_the_data(monkeypatch, module: str) -> None:
    """``module``'s method refuses the whole excitation (as PARSIM-K's predictor can, with a
    pole at 1): the refit on all the data fails and the model the sweep scored is kept."""
    import dataclasses

    from sysid import cli_options

    def refusing(name, **kwargs):
        meth, options = cli_options.method_options(name, **kwargs)

        def identify(data, **kw):
            flights = [data] if isinstance(data, sysid.IOData) else list(data or [])
            if sum(f.n_samples for f in flights) == N_EXC:
                raise sysid.OrderError("the predictor A_K of order 4 has a pole at |z| = 1")
            return meth.function(data, **kw)

        return dataclasses.replace(meth, function=identify), options

    monkeypatch.setattr(f"{module}.method_options", refusing)


@pytest.mark.parametrize("command", ["sweep", "identify"])
@pytest.mark.parametrize("refit_fails", [False, True])
def test_the_saved_line_says_what_the_saved_model_is(flights, tmp_path, monkeypatch, command,
                                                     refit_fails) -> None:
    """"model saved to X (identified again on all the data)" followed a warning that the
    refit was not kept: the line (and the model's provenance) now say which model it is."""
    if refit_fails:
        _refusing_all_the_data(monkeypatch, "sysid.cli" if command == "sweep"
                               else "sysid.cli_identify")
    out = tmp_path / "m.h5"
    res = run(command, flights[0].path, "--method", "iem", "--focus", "prediction",
              "--pasts", "10", "--futures", "10", "--orders", "4", "--out", out) \
        if command == "sweep" else run(command, flights[0].path, "--method", "iem", "--focus",
                                       "prediction", "--past", "10", "--future", "10",
                                       "--out", out)
    assert res.exit_code == 0, res.output
    model = sysid.load_model(out)
    saved = [ln for ln in res.stdout.splitlines() if ln.startswith("model saved to")]
    if refit_fails:
        assert "kept the model the sweep scored" in " ".join(res.stdout.split())
        assert model.provenance["n_samples"][0] < N_EXC
        assert model.provenance["selection"]["identified_again"] is False
        assert saved == [f"model saved to {out} (the model the sweep scored, identified on "
                         f"{model.provenance['selection']['data'].split()[2]} of the {N_EXC} "
                         "samples)"], res.stdout
        if command == "identify":  # the samples line agrees: it had counted all as identified
            used = model.provenance["selection"]["data"]
            assert f"loaded {N_EXC} samples" in res.stdout
            assert f"the model is the one the sweep scored, {used}" in res.stdout
            assert "identified from" not in res.stdout
    else:
        assert model.provenance["n_samples"] == [N_EXC]
        assert model.provenance["selection"] == {"identified_again": True,
                                                 "data": "all the data"}
        assert saved == [f"model saved to {out} (identified again on all the data)"]


def test_identify_with_every_setting_given_saves_without_a_selection(flights, tmp_path):
    out = tmp_path / "m.h5"
    res = run("identify", flights[0].path, *FAST, "--out", out)
    assert res.exit_code == 0, res.output
    assert f"model saved to {out}\n" in res.stdout and "not saved" not in res.stdout
    assert "selection" not in sysid.load_model(out).provenance
    res = run("identify", flights[0].path, *FAST)  # shown, then gone: it says so
    assert res.exit_code == 0 and "model not saved: --out FILE.h5 saves it" in res.stdout


def test_sweep_and_identify_choose_alike_with_no_knobs(flights, tmp_path) -> None:
    """On one closed-loop session both commands run sysid.auto.select (held-out split, default
    grid, both focus choices): the same past, future, order and focus, and the model the
    sweep saves is the one identify returns."""
    ident = run("identify", flights[0].path, "--json")
    assert ident.exit_code == 0, ident.output
    chose = json.loads(ident.stdout)["selection"]
    out = tmp_path / "swept.h5"
    swept = run("sweep", flights[0].path, "--out", out, "--json")
    assert swept.exit_code == 0, swept.output
    report = json.loads(swept.stdout)

    def key(sel: dict) -> tuple:
        return (sel["chosen"]["past"], sel["chosen"]["future"], sel["chosen"]["order"],
                sel["focus"], sel["method"])

    assert key(report) == key(chose) and report["grid"] == chose["grid"]
    # the grid is set by the data's memory (samples), and the report says it
    memory = chose["memory_samples"]
    assert isinstance(memory, int) and memory >= 1 and report["memory_samples"] == memory
    assert chose["grid"]["pasts"][0] <= memory <= chose["grid"]["pasts"][-1]
    assert set(report["focus_scores"]) == {"prediction", "simulation"}
    assert report["focus_scores"] == pytest.approx(chose["focus_scores"])
    assert report["best"] == report["chosen"] and report["rule"] == chose["rule"]
    model = sysid.load_model(out)
    assert (model.provenance["past"], model.provenance["future"], model.A.shape[0],
            model.provenance["focus"], model.provenance["method"]) == key(chose)
    assert pole_error(flights[0].system.poles(), model.poles()) < 0.03
    # no --method: PARSIM-K was tried at the chosen horizons, and the report says which won
    assert chose["method_note"].startswith(f"method {chose['method']}: at past")
    assert json.loads(ident.stdout)["method"] == chose["method"]


def test_a_named_method_is_not_replaced(flights) -> None:
    res = run("sweep", flights[0].path, "--pasts", "10", "--futures", "10", "--orders", "3,4",
              "--method", "iem", "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["method"] == "iem" and report["method_note"] == ""


def test_sweep_reports_the_best_candidates_and_the_grid_edge(flights) -> None:
    res = run("sweep", flights[0].path, "--pasts", "10,20", "--futures", "10",
              "--orders", "2,3", "--focus", "prediction", "--top", "3", "--method", "iem")
    assert res.exit_code == 0, res.output
    text = " ".join(res.stdout.split())
    assert "best 3 candidates of 4" in text and "acc.z" in text and "gyro.x" in text
    assert "chosen: past" in text and "order 3, method iem, focus prediction" in text
    assert ("warning: order 3 is the largest tried: the best may lie beyond; extend --orders "
            "beyond 3") in text  # the values given: the option to extend
    assert "futures [10], orders [2, 3]" in text  # the orders swept, not a range of them
    assert "progress counted" not in text  # one focus given: one grid
    both = run("sweep", flights[0].path, "--pasts", "10,20", "--futures", "10", "--orders",
               "2,3", "--top", "3", "--method", "iem")  # the focus chosen: both grids run
    assert both.exit_code == 0, both.output
    assert ("best 3 candidates of 4 with the chosen focus (the progress counted both focuses' "
            "grids)") in " ".join(both.stdout.split())


def test_export_round_trip(flights, tmp_path) -> None:
    src = tmp_path / "m.h5"
    flights[0].system.save(src)
    for fmt in ("json", "mat"):
        res = run("export", src, "--format", fmt)
        assert res.exit_code == 0, res.output
        back = sysid.load_model(src.with_suffix(f".{fmt}"))
        np.testing.assert_allclose(back.A, flights[0].system.A)
        assert back.output_names == flights[0].system.output_names
    again = run("export", src, "--format", "json")
    assert again.exit_code == 2 and "already exists" in again.stderr
    # the format from --out's suffix (it was required even for an --out ending in .mat)
    res = run("export", src, "--out", tmp_path / "as.MAT")
    assert res.exit_code == 0, res.output
    np.testing.assert_allclose(sysid.load_model(tmp_path / "as.MAT").A, flights[0].system.A)


def test_method_names_are_taken_in_any_case() -> None:
    """``--method IEM`` or ``PO-MOESP``, as papers write them, was "unknown"."""
    from sysid.methods import get_method

    assert get_method("PO-MOESP").name == "po-moesp"
    assert get_method("IEM").name == get_method("iem").name
    assert run("identify", "--method", "IEM", "--help").exit_code == 0


def test_parse_grid() -> None:
    assert list(parse_grid(text="20:80:10", option="--pasts")) == [20, 30, 40, 50, 60, 70, 80]
    assert list(parse_grid(text="6,8", option="--orders")) == [6, 8]
    assert list(parse_grid(text="3:5", option="--orders")) == [3, 4, 5]
    huge = parse_grid(text="1:100000000", option="--pasts")  # lazy: no list of 1e8 ints
    assert isinstance(huge, range) and len(huge) == 100_000_000
    for text in ("-2:1", "0:1", "0", "1,-3"):  # ranges are checked like single values
        with pytest.raises(ParameterError, match="positive integers"):
            parse_grid(text=text, option="--pasts")
    with pytest.raises(ParameterError, match=">= 2"):
        parse_grid(text="1:4", option="--futures", minimum=2)
    with pytest.raises(ParameterError, match="at most 500"):  # a lazy range, by its stop
        parse_grid(text="2:100000000", option="--orders", maximum=500)


def test_sweep_refuses_orders_no_model_file_holds_before_it_runs(flights) -> None:
    res = run("sweep", flights[0].path, "--pasts", "10", "--futures", "10", "--orders", "4,600")
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "--orders '4,600': at most 500" in res.output


@pytest.mark.parametrize(("args", "words"), [
    (["identify", "{missing}"], ["no such file"]),
    (["identify", "{text}"], ["not an HDF5 file"]),
    (["identify", "{f0}", "--window", "hover"], ["no phase 'hover'"]),
    (["identify", "{f0}", "--inputs", "baro"], ["no log stream or variable 'baro'",
                                                 "choose the inputs with --inputs"]),
    (["identify", "{f0}", "--outputs", "Gyro"], ["(did you mean 'gyro'?)",
                                                 "choose the outputs with --outputs"]),
    (["identify", "{f0}", "--order", "400", "--past", "5", "--future", "3"], ["order"]),
    (["identify", "{f0}", "--dt", "1e9"], ["dt=1e+09 s is longer than the"]),
    (["identify", "{f0}", "--window", "a:b"], ["--window"]),
    (["sweep", "{f0}", "--pasts", "80:20"], ["--pasts"]),
    (["compare", "{missing}", "{f0}"], ["does not exist"]),
    (["export", "{text}", "--format", "mat"], ["model file"]),
    (["identify", "{f0}", *FAST, "--rrd", "{tmp}/x.rrd"], ["--rrd"]),
])
def test_user_mistakes_exit_2_with_one_line(flights, tmp_path, monkeypatch, args, words) -> None:
    monkeypatch.setitem(sys.modules, "sysid.viz", None)  # as if viz were not installed
    text = tmp_path / "notes.txt"
    text.write_text("hello\n")
    paths = {"missing": tmp_path / "nope.h5", "text": text, "f0": flights[0].path,
             "tmp": tmp_path}
    res = run(*[a.format(**paths) for a in args])
    assert res.exit_code == 2, res.output
    err = res.stderr.strip()
    assert err.startswith("error:") and "\n" not in err and "Traceback" not in res.output, err
    assert all(w in err for w in words), err


def test_rrd_reports_are_written(flights, tmp_path) -> None:
    from tests.viz.rrd import load

    out = tmp_path / "id.rrd"
    res = run("identify", flights[0].path, *FAST, "--rrd", out)
    assert res.exit_code == 0, res.output
    model = sysid.iem(sysid.session_io.load_session(flights[0].path, outputs=["acc.z", "gyro"]),
                      order=4, past=20, future=10)
    ents = load(out, sort_by=None)
    poles = np.array(ents["/sysid/poles/A"].static["Points2D:positions"], dtype=float)
    assert poles.shape == (4, 2)
    np.testing.assert_allclose(np.sort_complex(poles[:, 0] + 1j * poles[:, 1]),
                               np.sort_complex(model.poles()), atol=1e-6)
    res = run("sweep", flights[0].path, "--pasts", "20", "--futures", "10", "--orders", "3,4",
              "--rrd", tmp_path / "sw.rrd")
    assert res.exit_code == 0 and "/sysid/sweep/poles/order_4" in load(tmp_path / "sw.rrd")


def _rrd_fits(ents, base: str, names, slugs=("windowed_simulation", "prediction_1_step")
              ) -> dict[str, dict[str, float]]:
    """``{mode slug: {channel: fit}}`` of the summary texts under ``base``; each model
    series' name (one experiment: its fit is the overall fit) must say the same."""
    out = {}
    for slug in slugs:
        text = ents[f"{base}/{slug}/summary"].static["TextDocument:text"][0]
        fits = {n: float(f) for n, f in re.findall(r"^  (\S+):\s+(\S+) %$", text, re.M)}
        assert list(fits) == list(names), text
        for n, f in fits.items():
            label = ents[f"{base}/{slug}/exp0/{n}/model"].static["SeriesLines:names"][0]
            assert f"(fit {f:.2f} %)" in label, (label, f)
        out[slug] = fits
    return out


def test_identify_validate_rrd_keeps_both_data_sets(flights, tmp_path) -> None:
    """`identify --validate --rrd`: the identification comparisons stay under /sysid/<mode>,
    the validation ones go under /sysid/validation/<mode>; each entity holds one flight's
    samples, and the summaries and series names carry the fits the command prints. (The
    validation results were written over the identification ones: two flights' samples on
    one `t` timeline, names and summaries of the validation fit only.)"""
    from tests.viz.rrd import load

    args = [flights[0].path, *FAST, "--validate", flights[1].path]
    res = run("identify", *args, "--json", "--rrd", tmp_path / "j.rrd")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    names = list(report["fit_percent"]["1-step"])
    # simulation as `sysid compare` does it by default: windows only for a pole near |z| = 1
    sim = "windowed_simulation" if report["simulation_window_s"] else "simulation"
    want = {"/sysid": {sim: report["fit_percent"]["simulation"],
                       "prediction_1_step": report["fit_percent"]["1-step"]},
            "/sysid/validation": {sim: report["validation"][0]["fit_percent"],
                                  "prediction_1_step": report["validation"][1]["fit_percent"]}}
    assert report["validation"][0]["mode"].startswith("validation: simulation")
    ents = load(tmp_path / "j.rrd", sort_by=None)
    for base, modes in want.items():
        got = _rrd_fits(ents, base, names, slugs=(sim, "prediction_1_step"))
        for slug, fits in modes.items():
            np.testing.assert_allclose([got[slug][n] for n in names], [fits[n] for n in names],
                                       atol=0.005 + 1e-9, err_msg=f"{base}/{slug}")
    # the two data sets' fits differ: neither was written over the other
    assert want["/sysid"] != want["/sysid/validation"]
    # each entity holds one flight: its samples, once each on `t`
    data = [sysid.session_io.load_session(f.path, outputs=["acc.z", "gyro"]) for f in flights]
    series = {e: ent for e, ent in ents.items() if "Scalars:scalars" in ent.rows}
    assert len(series) == 2 * 2 * 2 * len(names)  # data sets x modes x (measured, model)
    for e, ent in series.items():
        d = data[1] if e.startswith("/sysid/validation/") else data[0]
        t = ent.times["t"]
        assert len(t) == d.n_samples and len(np.unique(t)) == len(t), e
        if e.endswith("/measured"):
            y = d.y[:, d.output_names.index(e.split("/")[-2])]
            np.testing.assert_allclose(ent.scalars()[np.argsort(t)], y, atol=1e-9, err_msg=e)
    # the text output prints the same fits, to its one decimal
    res = run("identify", *args, "--rrd", tmp_path / "t.rrd")
    assert res.exit_code == 0, res.output
    ents = load(tmp_path / "t.rrd", sort_by=None)
    lines = res.stdout.splitlines()
    for base, rows in (("/sysid", ("simulation", "1-step prediction")),
                       ("/sysid/validation", ("validation: simulation",
                                              "validation: 1-step prediction"))):
        got = _rrd_fits(ents, base, names, slugs=(sim, "prediction_1_step"))
        for slug, label in zip((sim, "prediction_1_step"), rows, strict=True):
            line = next(ln for ln in lines if ln.startswith(label))
            printed = [float(v) for v in line.split()[-len(names):]]
            np.testing.assert_allclose(printed, [got[slug][n] for n in names],
                                       atol=0.05 + 0.005 + 1e-9, err_msg=line)


@pytest.mark.parametrize("command", ["identify", "compare", "order", "sweep", "export"])
def test_help_has_an_example(command) -> None:
    res = run(command, "--help")
    assert res.exit_code == 0 and "Example" in res.stdout


def test_order_with_horizons_given_needs_no_default_grid(tmp_path) -> None:
    """A record too short for the default grid (which refuses it) is analysed at the horizons
    the caller gives: ``sysid order`` no longer builds the default grid it does not use."""
    phases = [(0.0, "takeoff", "takeoff"), (0.3, "excitation", "excitation"),
              (1.1, "landing", "landing")]
    short = write_flight(tmp_path / "short.h5", system=known_system(), seed=3, n=50,
                         n_drop=0, phases=phases)
    refused = run("order", short.path)
    assert refused.exit_code == 2 and "--past/--future" in refused.output
    # each command names its own options: `order` has no --order, `sweep` takes ranges
    assert "give horizons (--past/--future), longer" in refused.stderr, refused.output
    refused = run("sweep", short.path)
    assert refused.exit_code == 2 and "after the held-out 30 %" in refused.stderr
    assert "(--pasts/--futures, and --orders)" in refused.stderr, refused.output
    res = run("order", short.path, "--past", "1", "--future", "2", "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert (report["past"], report["future"]) == (1, 2) and report["suggested_order"] >= 1


def test_identify_does_not_score_a_validation_record_too_short_to_mean_anything(flights,
                                                                                tmp_path,
                                                                                caplog):
    """`identify --validate` scored a 15-sample validation window (0.3 s windows, fits that
    only measured the initial state) that `sysid compare` refuses: it now says so, keeps the
    identification's rows and still saves the model."""
    short = write_flight(tmp_path / "short.h5", system=known_system(), seed=3,
                         phases=[(0.0, "takeoff", "takeoff"), (10.0, "prbs", "excitation"),
                                 (10.3, "land", "landing")])
    out = tmp_path / "m.h5"
    res = run("identify", flights[0].path, *FAST, "--validate", short.path, "--out", out)
    assert res.exit_code == 0, res.output
    assert "validation not scored: short.h5 has 15 samples" in caplog.text
    assert "too few to score a model on" in caplog.text
    assert "validation: simulation" not in res.stdout and out.is_file()
    assert run("compare", out, short.path).exit_code == 2  # the rule is compare's
    res = run("identify", flights[0].path, *FAST, "--validate", short.path, "--json")
    assert json.loads(res.stdout)["validation"] == []
    # one short record among others leaves only itself out (it cancelled every row: review)
    caplog.clear()
    res = run("identify", flights[0].path, *FAST, "--validate", flights[1].path,
              "--validate", short.path, "--json")
    assert res.exit_code == 0, res.output
    assert "validation not scored on these: short.h5 has 15 samples" in caplog.text
    assert "validate on records of 0.4 s at least" in caplog.text  # identify has no --window
    assert len(json.loads(res.stdout)["validation"]) == 2  # f1's simulation and prediction


@pytest.mark.parametrize("command", [["compare", "m.h5", "s.h5"], ["sweep", "s.h5"]])
def test_a_window_of_1e308_seconds_is_refused_in_one_line(command):
    """It overflowed the window's sample count (OverflowError traceback, CLI fuzz)."""
    res = CliRunner().invoke(main, [*command, "--window-s", "1e308"], prog_name="sysid")
    assert res.exit_code == 2
    assert res.output.strip().splitlines() == [
        f"error: Invalid value for '--window-s': 1e+308 is above 86400 (see 'sysid "
        f"{command[0]} -h')"]


def test_identify_refuses_to_save_a_model_that_diverges_on_its_own_data(flights, tmp_path,
                                                                        monkeypatch):
    """Fixed settings the data did not support gave poles at |z| = 10.9, "diverged" in every
    cell of the fit table, "model saved", exit 0 (first-day review)."""
    import sysid.cli_identify as cli_identify

    real = cli_identify.method_options

    def diverging(*args, **kwargs):
        meth, options = real(*args, **kwargs)

        class Unstable:
            def identify(self, *a, **kw):
                model = meth.identify(*a, **kw)
                return model.replace(A=model.A * 12.0, K=model.K * 0.0)

        return Unstable(), options

    monkeypatch.setattr(cli_identify, "method_options", diverging)
    out = tmp_path / "m.h5"
    res = run("identify", flights[0].path, *FAST, "--out", out)
    assert res.exit_code == 2, res.output
    line = res.output.strip().splitlines()[-1]
    assert line.startswith("error: the model diverges on the data it was identified from")
    assert line.endswith("; nothing saved") and "try a lower --order" in line
    assert not out.exists()


def test_compare_on_a_session_without_the_models_channels_names_the_model(flights, tmp_path):
    """It said "no log stream or variable 'stabilizer.roll' for the outputs ... (use STREAM or
    STREAM.FIELD ...)", for a name the user never typed and with no option to act on it."""
    model = sysid.StateSpaceModel(A=np.eye(1) * 0.5, B=np.ones((1, 4)), C=np.ones((1, 1)),
                                  dt=0.02, input_names=[f"motor.m{i}" for i in range(1, 5)],
                                  output_names=["stabilizer.roll"])
    path = model.save(tmp_path / "m.json")
    for command in ("compare", "resid"):
        res = run(command, path, flights[0].path)
        assert res.exit_code == 2, res.output
        assert res.stderr.strip() == (
            f"error: {flights[0].path}: the model's output 'stabilizer.roll' is not logged in "
            "this session (its log streams: acc, gyro, motors); "
            f"{'compare' if command == 'compare' else 'analyse'} the model on sessions that "
            "log the channels it was identified with")


def test_a_long_channel_name_is_cut_in_the_message(flights, tmp_path):
    """A model file whose output is named by 150 000 characters had the name echoed whole in
    the "not logged" line (review D); so did --outputs in "no log stream or variable"."""
    long = "x" * 150_000
    model = sysid.StateSpaceModel(A=np.eye(1) * 0.5, B=np.ones((1, 4)), C=np.ones((1, 1)),
                                  dt=0.02, input_names=[f"motor.m{i}" for i in range(1, 5)],
                                  output_names=[long])
    path = model.save(tmp_path / "m.json")
    res = run("compare", path, flights[0].path)
    assert res.exit_code == 2, res.output
    cut = f"'{'x' * 60}'... (150000 characters)"
    assert res.stderr.strip() == (
        f"error: {flights[0].path}: the model's output {cut} is not logged in this session "
        "(its log streams: acc, gyro, motors); compare the model on sessions that log the "
        "channels it was identified with")
    res = run("order", flights[0].path, "--outputs", long)
    assert res.exit_code == 2, res.output
    assert f"no log stream or variable {cut} for the outputs" in res.stderr
    assert len(res.stderr) < 500, res.stderr
