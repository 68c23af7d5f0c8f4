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


def test_orders_a_method_cannot_identify_are_marked_not_fatal() -> None:
    """PARSIM-K refuses an order whose predictor A_K has a pole outside the unit circle. Such an
    order used to end ``information_criteria`` (and ``sysid order``) with that one error, the
    other orders' criteria lost; it is now listed in ``failed`` with its reason, holds NaN, and
    the smallest-criterion choices are among the orders that were scored. When every order
    fails the error is one line naming them."""
    import sysid
    from sysid.errors import OrderError
    from tests.sysid.systems import pbsid_example1_closed_loop

    data = pbsid_example1_closed_loop(rng=np.random.default_rng(0), n_samples=1500).data
    ic = sysid.information_criteria(data, orders=range(1, 11), past=3, future=6,
                                    method="parsim-k")
    bad = sorted(ic.failed)
    assert bad and bad[0] > 1 and set(bad) < set(range(1, 11))  # some, not all
    for n, why in ic.failed.items():
        assert "\n" not in why and f"order {n} has a pole" in why, why
    mask = np.isin(ic.orders, bad)
    for values in (ic.log_det, ic.aic, ic.aicc, ic.bic):
        assert values.shape == (10,) and np.isnan(values[mask]).all()
        assert np.isfinite(values[~mask]).all()
    assert ic.n_params.shape == (10,) and (ic.n_params > 0).all()  # defined for every order
    assert ic.scored.tolist() == [n for n in range(1, 11) if n not in ic.failed]
    for name, values in (("aic", ic.aic), ("aicc", ic.aicc), ("bic", ic.bic)):
        assert ic.chosen[name] == ic.orders[~mask][np.argmin(values[~mask])]
    assert ic.chosen["bic"] == 4  # the true order
    with pytest.raises(OrderError) as err:
        sysid.information_criteria(data, orders=[9, 10], past=3, future=6, method="parsim-k")
    msg = str(err.value)
    assert "\n" not in msg and "none of the orders 9, 10" in msg
    assert "order 9: " in msg and "order 10: " in msg


def test_a_gap_at_an_order_that_failed_defers_to_bic() -> None:
    """The gap rule would suggest an order the method could not identify: BIC's order is
    suggested instead, and the reason says why."""
    sv = np.array([10.0, 8.0, 6.0, 5.0, 0.1, 0.09, 0.08, 0.07])  # 1.7 decades after s_4
    base = _ic(5)
    bic = base.bic.copy()
    bic[3] = np.nan
    ic = InformationCriteria(orders=base.orders, n_params=base.n_params, log_det=base.log_det,
                             aic=base.aic, aicc=base.aicc, bic=bic, n_samples=1000,
                             chosen=base.chosen, failed={4: "PARSIM-K: the predictor A_K of "
                                                            "order 4 has a pole at |z| = 1.08"})
    hint = suggest_order(sv, ic)
    assert (hint.order, hint.rule, hint.by_rule["gap"]) == (5, "bic", 4)
    assert "order 4 could not be identified (PARSIM-K" in hint.reason and "\n" not in hint.reason


def test_cli_order_lists_failed_orders_and_prints_the_rest(session, monkeypatch) -> None:
    """``sysid order --method parsim-k`` at horizons where some orders' predictors are
    unstable (here 5, 7, 8 of 1..8) printed only ``error: PARSIM-K: the predictor A_K of
    order 5 ...``, whose advice (a lower order) the command has no option for. It prints the
    singular values and the table, failed orders marked with their reason and never starred;
    JSON holds ``null`` and the reasons. Only when every order fails is it one error line."""
    args = ["order", str(session.path), "--past", "5", "--future", "3", "--method", "parsim-k"]
    res = CliRunner().invoke(main, [*args, "--json"])
    assert res.exit_code == 0, res.output
    ic = json.loads(res.stdout)["information_criteria"]
    assert ic["orders"] == list(range(1, 9)) and ic["failed"]
    for n, why in ic["failed"].items():
        assert f"order {n} has a pole" in why
        assert all(ic[k][int(n) - 1] is None for k in ("aic", "aicc", "bic"))
        assert int(n) not in ic["chosen"].values()
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    rows = {line.split()[0]: line for line in res.stdout.splitlines()
            if line.split() and line.split()[0].isdigit()}
    for n in ic["failed"]:
        assert "failed: PARSIM-K: the predictor A_K of order" in rows[n] and "*" not in rows[n]
    assert f"{len(ic['failed'])} of 8 orders could not be identified" in res.stdout
    assert "suggested order:" in res.stdout

    def fail(*_args, order, **_kwargs):
        raise sysid_errors.OrderError(f"PARSIM-K: the predictor A_K of order {order} has a pole")

    from sysid import errors as sysid_errors
    monkeypatch.setattr("sysid.order._log_det", fail)
    res = CliRunner().invoke(main, args)
    err = res.stderr.strip()
    assert res.exit_code == 2 and err.startswith("error: parsim-k identified none of the orders "
                                                 "1..8") and "\n" not in err, res.output


def test_a_modest_gap_gives_way_when_every_criterion_picks_more_states() -> None:
    """0.5 decades after s_3 while AIC, AICc and BIC all pick 6 (a demo flight: gap 3, every
    criterion 11, held-out validation 8; order 3 fitted acc.z 0 %): BIC's order."""
    sv = np.array([10.0, 9.0, 8.0, 2.5, 2.0, 1.6, 0.5, 0.45])  # 0.5 decades after s_3
    hint = suggest_order(sv, _ic(6))
    assert (hint.order, hint.rule, hint.by_rule["gap"]) == (6, "bic", 3)
    assert "under 1), but AIC, AICc and BIC all pick more states (8, 8, 6)" in hint.reason
    strong = np.array([10.0, 9.0, 8.0, 0.5, 0.4, 0.3, 0.2, 0.1])  # 1.2 decades: the gap holds
    assert suggest_order(strong, _ic(6)).rule == "gap"
    assert suggest_order(sv, _ic(2)).rule == "gap"  # BIC picks fewer: no consensus for more
