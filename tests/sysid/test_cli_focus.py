"""--focus/--stability on the CLI, and compare's default mode for integrating models (issue 10)."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

import sysid
from sysid.cli import main
from tests.sysid.flights import known_system, write_flight

FAST = ["--order", "4", "--past", "20", "--future", "10"]


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    return write_flight(tmp_path_factory.mktemp("focus") / "f.h5", system=known_system(),
                        seed=21)


def run(*args: object) -> object:
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.mark.parametrize(("method", "focus"), [("iem", "simulation"), ("po-moesp", "prediction")])
def test_identify_takes_focus_and_stability(flight, tmp_path, method, focus) -> None:
    out = tmp_path / "m.h5"
    res = run("identify", flight.path, *FAST, "--method", method, "--focus", focus,
              "--stability", "enforce", "--out", out, "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["focus"] == focus
    model = sysid.load_model(out)
    assert model.provenance["focus"] == focus and model.provenance["stability"] == "enforce"
    assert max(abs(model.poles())) < 1.0


def test_bad_focus_is_one_line(flight) -> None:
    res = run("identify", flight.path, *FAST, "--focus", "both")
    assert res.exit_code == 2 and "--focus" in res.output
    assert "Traceback" not in res.output


def test_compare_simulates_integrating_models_over_windows_and_json_has_null(flight,
                                                                             tmp_path) -> None:
    """An integrator simulated over a whole flight only measures its drift: compare's default
    mode is then 2 s windows, and a diverged fit is null in JSON, never -1e27."""
    base = sysid.load_model(_identified(flight, tmp_path))
    integrating = base.replace(A=_with_integrator(base.A))
    path = tmp_path / "int.h5"
    integrating.save(path)
    res = run("compare", path, flight.path, "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["modes"][0]["mode"].startswith("simulation, 2 s windows")
    diverging = integrating.replace(A=1.2 * integrating.A)
    path2 = tmp_path / "div.h5"
    diverging.save(path2)
    res = run("compare", path2, flight.path, "--json", "--window-s", "1000")
    assert res.exit_code == 0, res.output
    fits = json.loads(res.stdout)["modes"][0]["overall"]
    assert all(v is None for v in fits.values()), fits
    res = run("compare", path2, flight.path, "--window-s", "1000", "--horizon", "100000")
    assert "diverged" in res.stdout
    # what a window or horizon beyond the record means is said where the mode is named
    assert "1000 s windows (longer than the records: each simulated whole)" in res.stdout
    assert re.search(r"100000-step prediction \(beyond the \d+-sample records: simulation\)",
                     res.stdout), res.stdout


@pytest.mark.parametrize(("pole", "kind"), [(1.0, "integrating or nearly"),
                                          (1.06, "integrating or nearly"),
                                          (1.1672, "unstable"),
                                          (-0.998, "lightly damped")])
def test_compare_words_the_pole_that_chose_windows(flight, tmp_path, pole, kind) -> None:
    """The note on stderr when compare falls back to windows said "integrating or nearly" for
    any pole at |z| >= 0.995; a pole at |z| = 1.1672 is unstable, not integrating. Near z = 1
    (within stability's NEAR_BAND) it is an integrator's estimate; beyond, outside the unit
    circle, unstable; inside but away from z = 1, lightly damped."""
    base = sysid.load_model(_identified(flight, tmp_path))
    path = tmp_path / "pole.h5"
    base.replace(A=_with_pole(base.A, pole)).save(path)
    res = run("compare", path, flight.path)
    assert res.exit_code == 0, res.output
    assert f"model has a pole at |z| = {abs(pole):.4f} ({kind}): simulation, 2 s windows" in (
        " ".join(res.stderr.split())), res.stderr


def test_compare_words_a_huge_pole_in_a_few_digits(flight, tmp_path) -> None:
    """A model file's pole at |z| = 8e302 was printed with 300 digits in the note (review D)."""
    base = sysid.load_model(_identified(flight, tmp_path))
    path = tmp_path / "huge.h5"
    base.replace(A=_with_pole(base.A, 8e302)).save(path)
    res = run("compare", path, flight.path)
    note = " ".join(res.stderr.split())
    assert re.search(r"model has a pole at \|z\| = 8(\.\d+)?e\+302 \(unstable\): simulation",
                     note), res.stderr
    assert not re.search(r"\d{20}", res.stderr), res.stderr


@pytest.fixture(scope="module")
def integrating(flight, tmp_path_factory):
    """The identified 4-state model with an integrator (compare's default: windows)."""
    tmp = tmp_path_factory.mktemp("integrating")
    base = sysid.load_model(_identified(flight, tmp))
    path = tmp / "int.h5"
    base.replace(A=_with_integrator(base.A)).save(path)
    return path


def _one_error_line(res) -> str:
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), res.output
    return lines[0]


@pytest.mark.parametrize(("args", "words"), [
    # 2 samples against a 4-state initial state scored 100.0 % on every channel, exit 0
    (["--window", "10:10.04"], ["f.h5 has 2 samples", "needs at least 20", "--window"]),
    (["--window", "10:10.3"], ["f.h5 has 15 samples", "needs at least 20"]),
    (["--window", "10:10.3", "--horizon", "1"], ["f.h5 has 15 samples"]),
    (["--window-s", "0.1"], ["--window-s 0.1 is 5 samples", "needs at least 20",
                             "--window-s 0.4 or longer"]),
])
def test_compare_refuses_records_and_windows_too_short_to_score(flight, integrating, args,
                                                                 words) -> None:
    """Every mode fits an initial state per record (per window): on fewer samples than the
    default window's floor (sysid.validate.min_fit_samples) that state alone fits them."""
    line = _one_error_line(run("compare", integrating, flight.path, *args))
    assert all(w in line for w in words), line


def test_compare_counts_ten_output_values_per_state(flight, integrating, tmp_path) -> None:
    """12 states seen through one output need 120 samples: 2 s (100) of a record is refused,
    though more than the 20-sample floor and the 2 s default."""
    base = sysid.load_model(integrating)
    n = 12
    lam = np.r_[1.0, np.linspace(0.2, 0.9, n - 1)]
    model = sysid.StateSpaceModel(A=np.diag(lam), B=np.ones((n, base.n_inputs)),
                                  C=np.ones((1, n)), dt=base.dt,
                                  input_names=base.input_names,
                                  output_names=base.output_names[-1:])
    path = tmp_path / "wide.h5"
    model.save(path)
    line = _one_error_line(run("compare", path, flight.path, "--window", "10:12"))
    assert "has 100 samples" in line and "12-state model on 1 output(s) needs at least 120" in (
        line), line
    res = run("compare", path, flight.path, "--window", "10:12.4")
    assert res.exit_code == 0, res.output
    assert "simulation, 2.4 s windows:" in res.stdout, res.stdout


def test_compare_titles_the_window_it_used(flight, integrating) -> None:
    """A record shorter than the default 2 s caps the window, and the title says the window
    used (it said "2 s windows" over 0.6 s); a --window-s beyond some records says so."""
    res = run("compare", integrating, flight.path, "--window", "10:10.6")
    assert res.exit_code == 0, res.output
    title = "simulation, 0.6 s windows (the shortest record: shorter than 2 s)"
    assert f"{title}: fit [%]" in res.stdout, res.stdout
    assert title in " ".join(res.stderr.split())
    res = run("compare", integrating, flight.path, "--window", "10:10.6", "--json")
    assert json.loads(res.stdout)["modes"][0]["mode"] == title
    res = run("compare", integrating, flight.path, "--window", "10:11", "--window-s", "2")
    assert "2 s windows (longer than the records: each simulated whole)" in res.stdout


def test_compare_says_when_a_window_is_longer_than_some_records(flight, integrating,
                                                                tmp_path) -> None:
    other = tmp_path / "short.h5"
    other.write_bytes(flight.path.read_bytes())
    res = run("compare", integrating, flight.path, other, "--window-s", "2",
              "--window", "short.h5=10:11")
    assert res.exit_code == 0, res.output
    assert "2 s windows (longer than some records: those simulated whole)" in res.stdout


def _with_pole(a: np.ndarray, pole: float) -> np.ndarray:
    """An A of the same size with real poles ``pole``, 0.5, 0.4, ... (random real basis)."""
    n = a.shape[0]
    basis = np.random.default_rng(0).standard_normal((n, n)) + 3 * np.eye(n)
    lam = np.r_[pole, 0.5 - 0.1 * np.arange(n - 1)]
    return basis @ np.diag(lam) @ np.linalg.inv(basis)


def _identified(flight, tmp_path):
    out = tmp_path / "base.h5"
    res = run("identify", flight.path, *FAST, "--out", out)
    assert res.exit_code == 0, res.output
    return out


def _with_integrator(a: np.ndarray) -> np.ndarray:
    """A with its largest eigenvalue moved onto z = 1 (same eigenvectors)."""
    lam, vec = np.linalg.eig(a)
    i = int(np.argmax(np.abs(lam)))
    lam = lam.copy()
    lam[i] = 1.0 if abs(lam[i].imag) < 1e-12 else lam[i] / abs(lam[i])
    if abs(lam[i].imag) > 0:
        j = int(np.argmin(np.abs(lam - np.conj(lam[i])) + (np.arange(lam.size) == i)))
        lam[j] = np.conj(lam[i])
    return (vec @ np.diag(lam) @ np.linalg.inv(vec)).real
