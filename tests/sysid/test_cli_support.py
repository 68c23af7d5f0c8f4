"""sysid.cli_support: the sysid group's one-line errors, --window values, fit cells and JSON,
the default compare mode, --rrd checks. (``parse_grid``: test_cli.py.)"""

from __future__ import annotations

import click
import numpy as np
import pytest
from click.testing import CliRunner

import sysid
from cfsession.errors import SessionError
from sysid.cli_support import (
    DIVERGED_FIT,
    Group,
    check_rrd,
    default_compare_mode,
    experiment_label,
    fit_or_none,
    fit_table,
    fits_json,
    parse_windows,
    split_names,
)
from sysid.comparison import CompareResult
from sysid.errors import ParameterError
from sysid.session_io import AUTO, PhaseRelative
from sysid.validate import INTEGRATING_RADIUS


def _group(exc: BaseException) -> click.Group:
    @click.group(cls=Group)
    def main() -> None:
        pass

    @main.command()
    def run() -> None:
        raise exc

    return main


@pytest.mark.parametrize(("exc", "line"), [
    (np.linalg.LinAlgError("SVD did not converge"),
     "error: numerical failure (SVD did not converge); try another order or horizons"),
    # one line whatever it holds: a line feed (in a file's name, say) shown escaped, not cut
    (sysid.OrderError("order=9 is too large\nsecond line"),
     "error: order=9 is too large\\nsecond line"),
    (SessionError("f.h5: no stream 'gyro'"), "error: f.h5: no stream 'gyro'"),
])
def test_user_errors_are_one_line_and_exit_2(exc, line):
    res = CliRunner().invoke(_group(exc), ["run"])
    assert res.exit_code == 2 and res.output.strip() == line


def test_a_bug_is_not_dressed_as_a_user_error():
    res = CliRunner().invoke(_group(KeyError("x")), ["run"])
    assert res.exit_code == 1 and isinstance(res.exception, KeyError)


def test_windows_for_every_session_and_for_one():
    common, own = parse_windows(["excitation", "b.h5=hover@1:4", " c.h5 = 2:7"])
    assert common == "excitation"
    assert own == {"b.h5": PhaseRelative(phase="hover", t0=1.0, t1=4.0), "c.h5": (2.0, 7.0)}
    assert parse_windows([]) == (AUTO, {})
    assert parse_windows(["all"])[0] is None


@pytest.mark.parametrize("texts", [["a.h5=prbs", " a.h5 =chirp"], ["prbs", "chirp"]])
def test_two_windows_for_one_session_are_refused(texts):
    """The last one won, silently: the first window was never read (walkthrough finding)."""
    with pytest.raises(ParameterError, match="two windows for") as info:
        parse_windows(["b.h5=hover", texts[0], texts[1]])
    assert repr(texts[0]) in str(info.value) and repr(texts[1]) in str(info.value)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("text", ["3:1", "a.h5=x@1", "1:nan"])
def test_a_bad_window_names_the_option(text):
    with pytest.raises(ParameterError) as info:
        parse_windows([text])
    assert str(info.value).startswith("--window ") and "\n" not in str(info.value)


def test_names_and_labels():
    assert split_names(" motors, gyro.x ,,acc") == ["motors", "gyro.x", "acc"]
    assert experiment_label("/data/sessions/f0.h5#airborne-2") == "f0.h5#airborne-2"
    assert experiment_label("relative/f1.h5") == "f1.h5"


def test_a_diverged_fit_is_none_in_json_and_diverged_in_tables():
    assert fit_or_none(DIVERGED_FIT) == DIVERGED_FIT and fit_or_none(87.25) == 87.25
    for bad in (DIVERGED_FIT - 1, -np.inf, np.nan, np.inf):
        assert fit_or_none(bad) is None
    table = fit_table(title="fit [%]", names=["gyro.x", "gyro.y"],
                      rows=[("f0.h5", np.array([91.24, -1e27]))])
    cells = [list(col.cells) for col in table.columns]
    assert cells == [["f0.h5"], ["91.2"], ["diverged"]]


def _model_with_pole(radius: float) -> sysid.StateSpaceModel:
    return sysid.StateSpaceModel(A=np.diag([radius, 0.5]), B=np.ones((2, 1)),
                                 C=np.ones((1, 2)), dt=0.02)


def test_default_compare_mode_simulates_integrators_over_windows():
    assert default_compare_mode(_model_with_pole(0.99)) == ("simulation", {})
    label, kw = default_compare_mode(_model_with_pole(INTEGRATING_RADIUS))
    assert label == "simulation, 2 s windows" and kw == {"window": pytest.approx(2.0)}
    slow = _model_with_pole(0.999).replace(dt=1.0)  # 2 s would be 2 samples: 20 at least
    assert default_compare_mode(slow)[1] == {"window": 20.0}


def test_check_rrd_refuses_before_any_work(tmp_path):
    data = tmp_path / "f.rrd"
    data.write_bytes(b"")
    assert check_rrd(None, inputs=[], force=False) is None
    assert check_rrd(tmp_path / "out.rrd", inputs=[], force=False) == tmp_path / "out.rrd"
    # a missing folder is made when the file is written, as every output's
    assert check_rrd(tmp_path / "no" / "x.rrd", inputs=[], force=False) == tmp_path / "no/x.rrd"
    assert check_rrd(data, inputs=[], force=True) == data  # replaced with --force only
    for path, inputs, force, words in (
            (tmp_path / "out.h5", [], False, "must end in .rrd"),
            (data, [data], True, "is an input of this command"),
            (data, [], False, "already exists; pass --force to replace it")):
        with pytest.raises(click.BadParameter, match=words):
            check_rrd(path, inputs=inputs, force=force)


def test_compare_result_json_names_channels():
    res = CompareResult(fit=np.array([80.0, np.nan]), fits=np.array([[70.0, np.nan]]),
                        y_model=(), y_measured=(), x0=(), horizon=None, window=None,
                        model_stable=True, predictor_stable=True, diverged=True,
                        output_names=("gyro.x", "gyro.y"))
    assert fits_json(res) == {"gyro.x": 80.0, "gyro.y": None}
    assert fits_json(res, res.fits[0]) == {"gyro.x": 70.0, "gyro.y": None}


def test_a_fit_cell_says_what_the_number_means() -> None:
    from sysid.cli_support import fit_cell

    # NaN: the measured channel does not move (zero denominator), not a diverged model
    assert [fit_cell(f) for f in (87.34, -12.0, -2e4, float("-inf"), float("nan"))] == [
        "87.3", "-12.0", "diverged", "diverged", "n/a"]
