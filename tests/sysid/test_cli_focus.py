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
