"""Order suggestions: which rule gave the order, never beyond what the method identifies."""

from __future__ import annotations

import json
import logging

import numpy as np
import pytest
from click.testing import CliRunner

from sysid.cli import main
from sysid.order import InformationCriteria, suggest_order
from tests.sysid.flights import known_system, write_flight


def _ic(bic: int, *, orders: int = 8) -> InformationCriteria:
    """Criteria over orders 1..``orders`` whose BIC is smallest at ``bic`` (AIC at the top)."""
    n = np.arange(1, orders + 1)
    bic_values = (n - bic) ** 2.0
    aic_values = -n.astype(float)
    return InformationCriteria(orders=n, n_params=10 * n, log_det=np.zeros(orders),
                               aic=aic_values, aicc=aic_values, bic=bic_values, n_samples=1000,
                               chosen={"aic": orders, "aicc": orders, "bic": bic})


def test_a_clear_gap_gives_the_order() -> None:
    sv = np.array([10.0, 8.0, 6.0, 5.0, 0.1, 0.09, 0.08, 0.07])  # 1.7 decades after s_4
    hint = suggest_order(sv, _ic(5))
    assert (hint.order, hint.rule, hint.gap_clear) == (4, "gap", True)
    assert hint.by_rule == {"gap": 4, "aic": 8, "aicc": 8, "bic": 5}
    assert "after s_4" in hint.reason and "BIC picks 5" in hint.reason
    assert hint.gaps.size == sv.size - 1 and hint.gap_decades == pytest.approx(np.log10(50))


def test_a_degenerate_or_small_gap_defers_to_bic() -> None:
    dominant = np.array([1000.0, 5.0, 4.0, 1.0, 0.9, 0.8, 0.7, 0.6])  # largest gap after s_1
    hint = suggest_order(dominant, _ic(4))
    assert (hint.order, hint.rule, hint.by_rule["gap"]) == (4, "bic", 1)
    assert "right after s_1" in hint.reason
    flat = np.geomspace(10.0, 1.0, 8)  # every gap 0.14 decades: no cut
    hint = suggest_order(flat, _ic(3))
    assert (hint.order, hint.rule, hint.gap_clear) == (3, "bic", False)
    assert "no clear cut" in hint.reason
    edge = suggest_order(flat, _ic(8))  # BIC at the largest order scored is flagged
    assert edge.order == 8 and "the best may lie beyond" in edge.reason


def test_the_gap_rule_stays_within_the_methods_order_limit() -> None:
    sv = np.array([10.0, 9.0, 8.0, 7.0, 6.0, 5.0, 0.01, 0.009])  # the drop is after s_6
    assert suggest_order(sv, _ic(6)).order == 6
    capped = suggest_order(sv, _ic(4, orders=4), max_order=4)  # the method allows 4 at most
    assert capped.by_rule["gap"] <= 4 and capped.order <= 4 and capped.gaps.size == 4
    assert suggest_order(sv, _ic(6), show=3).gaps.size == 2


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    return write_flight(tmp_path_factory.mktemp("order") / "f.h5", system=known_system(),
                        seed=21)


def test_cli_scores_and_suggests_only_orders_the_method_identifies(session, caplog) -> None:
    """With future 3 and 4 outputs the methods identify orders up to (3 - 1) x 4 = 8: the
    criteria stop there (order 9 used to end the command with an error) and the suggestion
    is one of them, with the command that identifies it. The models of the criteria are
    quiet (a warning per order about poles kept outside the unit circle flooded the log)."""
    for method in ("iem", "po_moesp"):
        with caplog.at_level(logging.WARNING):
            res = CliRunner().invoke(main, ["order", str(session.path), "--past", "5",
                                            "--future", "3", "--method", method, "--json"])
        assert not [r for r in caplog.records if r.name == "sysid.stability"]
        assert res.exit_code == 0, res.output
        report = json.loads(res.stdout)
        assert report["method"] == method.replace("_", "-") and report["max_order"] == 8
        assert report["information_criteria"]["orders"] == list(range(1, 9))
        assert 1 <= report["suggested_order"] <= 8
        assert report["suggestion"]["rule"] in ("gap", "bic")
    res = CliRunner().invoke(main, ["order", str(session.path), "--past", "20", "--future",
                                    "10"])
    assert res.exit_code == 0, res.output
    text = " ".join(res.stdout.split())
    assert "suggested order: 4, by the singular values drop" in text
    assert "--method iem --past 20 --future 10 --order 4" in text


def test_the_rank_cap_of_a_short_past_is_not_a_gap() -> None:
    """With past = 1 and m + l = 4 channels the matrix has rank 4 whatever the data: the values
    after s_4 are zero. That drop (about 300 decades) is the cap, not the data's order."""
    import sysid
    from sysid.order import information_criteria
    from tests.sysid.systems import open_loop, random_stable_system

    rng = np.random.default_rng(12)
    system = random_stable_system(n_states=6, n_inputs=2, n_outputs=2, rng=rng)
    data = open_loop(system, n_samples=1500, rng=rng, noise_std=0.1).data
    sv = sysid.singular_values(data, past=1, future=10)
    assert sv[4] <= 1e-12 * sv[0]  # the cap
    ic = information_criteria(data, orders=range(1, 5), past=1, future=10)
    hint = suggest_order(sv, ic, max_order=4)
    assert hint.rule == "bic" and not hint.gap_clear and hint.gaps.size == 3
    assert hint.gap_decades < 5 and hint.by_rule["gap"] < 4
    assert "rank cap" in hint.reason and "longer past" in hint.reason
    assert "\n" not in hint.reason
