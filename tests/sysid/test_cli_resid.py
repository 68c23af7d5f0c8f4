"""`sysid resid`, `sysid compare --residuals` and the residual panels of the .rrd report."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

import sysid
from sysid.cli import main
from tests.sysid.flights import known_system, write_flight
from tests.viz.rrd import load


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    d = tmp_path_factory.mktemp("resid")
    system = known_system()
    flights = [write_flight(d / f"f{i}.h5", system=system, seed=20 + i) for i in range(2)]
    model_path = d / "m.h5"
    res = CliRunner().invoke(main, ["identify", str(flights[0].path), "--order", "4", "--past",
                                    "20", "--future", "10", "--out", str(model_path)])
    assert res.exit_code == 0, res.output
    return flights, model_path


def run(*args: object):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_resid_json_matches_the_api(setup) -> None:
    flights, model_path = setup
    res = run("resid", model_path, flights[1].path, "--max-lag", "15", "--json")
    assert res.exit_code == 0, res.output
    report = json.loads(res.stdout)
    assert report["max_lag"] == 15 and len(report["outputs"]) == 4
    out = report["outputs"][0]
    assert len(out["autocorr"]) == 16 and len(out["inputs"][0]["crosscorr"]) == 31
    assert out["autocorr"][0] == pytest.approx(1.0)
    assert all(isinstance(o["white"], bool) for o in report["outputs"])


LEGEND = ("white ", "Ljung-Box", "worst input (p)", "reading p:", "p ~ 0")


@pytest.mark.parametrize("command", ["resid", "compare"])
def test_the_table_is_explained_in_text_and_not_in_json(setup, command) -> None:
    """The review: `compare --residuals` printed "99% bounds (auto ±0.036)", "white outside Q
    p indep. outside worst input (p)" and no word on them. One legend, after the table, for
    both commands; their --json has no table, so no legend."""
    flights, model_path = setup
    extra = ["--residuals"] if command == "compare" else []
    res = run(command, model_path, *(f.path for f in flights), *extra)
    assert res.exit_code == 0, res.output
    text = res.stdout
    table_at = text.index("output  white")
    legend = text[text.index("\n  white ", table_at) + 1:]
    assert all(word in legend for word in LEGEND), legend
    n = re.search(r"residual analysis: (\d+) samples", text).group(1)  # where p is read
    assert f"over {n} samples" in legend and "±" in legend
    assert "p >= 0.01" in legend and "0.0025 (0.01/4)" in legend  # 99 %, Bonferroni over 4
    assert len(legend.splitlines()) <= 12 and max(map(len, legend.splitlines())) <= 110
    if command == "resid":  # the same text for both: one piece of code
        other = run("compare", model_path, *(f.path for f in flights), "--residuals").stdout
        assert other.endswith(legend)
    res = run(command, model_path, *(f.path for f in flights), *extra, "--json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)  # nothing but the JSON document
    assert not any(word in res.stdout for word in ("Ljung-Box", "reading p"))
    # compare --residuals --json carries the analysis as resid --json gives it (it left it out)
    analysis = doc["residuals"] if command == "compare" else doc
    resid_doc = json.loads(run("resid", model_path, *(f.path for f in flights), "--json").stdout)
    assert {k: v for k, v in analysis.items() if k != "model"} == {
        k: v for k, v in resid_doc.items() if k != "model"}


def test_compare_residuals_prints_the_summary(setup) -> None:
    flights, model_path = setup
    res = run("compare", model_path, *(f.path for f in flights), "--residuals")
    assert res.exit_code == 0, res.output
    assert "residual analysis" in res.stdout and "white" in res.stdout
    # the table's columns line up whatever the numbers' lengths (p down to 1e-200 and 0)
    lines = res.stdout[res.stdout.index("output  white"):].splitlines()
    table = lines[:1 + len(sysid.load_model(model_path).output_names)]
    cells = [[m.span() for m in re.finditer(r"\S+(?: \S+)*", line)] for line in table]
    assert all(len(c) == len(cells[0]) for c in cells), table
    for col in range(len(cells[0])):  # every column starts alike (text) or ends alike (numbers)
        assert len({c[col][0] for c in cells}) == 1 or len({c[col][1] for c in cells}) == 1, (
            col, table)


def test_resid_writes_residual_panels(setup, tmp_path) -> None:
    flights, model_path = setup
    rrd = tmp_path / "r.rrd"
    res = run("resid", model_path, flights[1].path, "--max-lag", "10", "--rrd", rrd)
    assert res.exit_code == 0, res.output
    ents = load(rrd, sort_by="lag")
    model = sysid.load_model(model_path)
    y, u = model.output_names[0], model.input_names[0]
    auto = ents[f"/sysid/residuals/{y}/autocorr/value"].scalars()
    upper = ents[f"/sysid/residuals/{y}/autocorr/upper"].scalars()
    assert auto.shape == (11,) and auto[0] == pytest.approx(1.0)
    assert np.allclose(upper, upper[0]) and 0 < upper[0] < 0.2
    cross = ents[f"/sysid/residuals/{y}/cross/{u}/value"].scalars()
    assert cross.shape == (21,) and np.all(np.abs(cross) < 1)
    assert "/sysid/residuals/summary" in ents


@pytest.mark.parametrize("args", [["--max-lag", "0"], ["--confidence", "2"],
                                  ["--max-lag", "100000"]])
def test_resid_bad_input_is_one_line(setup, args) -> None:
    flights, model_path = setup
    res = run("resid", model_path, flights[1].path, *args)
    assert res.exit_code == 2
    assert "Traceback" not in res.output and len(res.output.strip().splitlines()) == 1


def test_order_prints_information_criteria(setup) -> None:
    flights, _ = setup
    res = run("order", flights[0].path, "--past", "20", "--future", "10", "--show", "8",
              "--json")
    assert res.exit_code == 0, res.output
    ic = json.loads(res.stdout)["information_criteria"]
    assert ic["orders"] == list(range(1, 9)) and ic["chosen"]["bic"] == 4
    table = run("order", flights[0].path, "--past", "20", "--future", "10", "--show", "8")
    assert "AIC picks" in table.stdout and "*" in table.stdout


def test_compare_records_the_residuals_it_prints(setup, tmp_path) -> None:
    """`compare --residuals --rrd` wrote the fits and left the residual panels out."""
    flights, model_path = setup
    rrd = tmp_path / "c.rrd"
    res = run("compare", model_path, flights[1].path, "--residuals", "--rrd", rrd)
    assert res.exit_code == 0, res.output
    y = sysid.load_model(model_path).output_names[0]
    assert load(rrd, sort_by="lag")[f"/sysid/residuals/{y}/autocorr/value"].scalars().size
