"""The ranking warning: its remedy fits whether validation flights were given, and it says when
no model beat the held-out mean."""

from __future__ import annotations

import dataclasses

import numpy as np

from sysid.auto import select
from sysid.methods import get_method
from sysid.parsimony import ranking_warning, score_se
from sysid.sweep import SweepResult, SweepRow
from tests.sysid.systems import open_loop, random_stable_system


def _row(order: int, errors: np.ndarray) -> SweepRow:
    fit = 100.0 * (1.0 - np.sqrt(errors.sum(axis=0)))
    return SweepRow(past=4, future=4, order=order, fit=fit, poles=np.zeros(order, complex),
                    stable=True, predictor_stable=True, seconds=0.0, errors=errors)


def test_given_validation_flights_are_asked_longer_or_more_not_given_again() -> None:
    """Every branch of the warning (too few blocks, several orders within the standard
    error, dominant blocks): with validation flights given, the remedy asks for longer ones
    or more of them and does not point at --validate as if none had been."""
    rng = np.random.default_rng(0)
    one = [_row(3, np.array([[0.01]]))]
    noisy = SweepResult(rows=tuple(_row(n, 0.02 * rng.gamma(1.0, size=(12, 1)) * (1 + 0.01 * n))
                                   for n in (3, 5)), method="iem", horizon=None,
                        window=1.0).ranked(require_stable=True)
    assert score_se(noisy[0]) >= 1.0
    base = 2e-4 * (1 + 0.1 * rng.standard_normal((14, 2)))
    base[[3, 9], [0, 1]] = 0.09  # one outlier's error each: two blocks dominate
    spiked = SweepResult(rows=tuple(_row(n, base * (1 + 0.001 * n)) for n in (3, 5)),
                         method="iem", horizon=None, window=1.0).ranked(require_stable=True)
    for ranked in (one, noisy, spiked):
        held_out = ranking_warning(ranked, n_samples=60)
        given = ranking_warning(ranked, n_samples=60, validation_given=True)
        # sysid identify's --validate flights score the chosen model and never rank: sweep's do
        assert "sysid sweep --validate" in held_out and "--validate" not in given
        assert given.startswith("the 60 held-out samples")
    assert "give longer ones or more of them" in ranking_warning(noisy, n_samples=60,
                                                                 validation_given=True)
    assert "validate on other flights" in ranking_warning(spiked, n_samples=60,
                                                          validation_given=True)


def test_a_selection_on_given_validation_flights_says_so() -> None:
    """200 noisy samples identify, 60 given validate: the selection's warning asks for
    longer or more of the validation flights, not for --validate."""
    rng = np.random.default_rng(0)
    system = random_stable_system(n_states=4, n_inputs=1, n_outputs=1, rng=rng,
                                  radius=(0.5, 0.9))
    ident, val = (open_loop(system, n_samples=n, rng=rng, noise_std=0.5).data
                  for n in (200, 60))
    meth = get_method("iem")
    sel = select([[ident]], validation=[val], method=meth, options=meth.options())
    (warned,) = [w for w in sel.warnings if "held-out samples" in w]
    assert "the 60 held-out samples" in warned and "--validate" not in warned
    assert "validation flights given are too short or too few" in warned


def test_when_no_model_beats_the_held_out_mean_the_warning_says_nothing_was_ranked() -> None:
    """Every held-out fit <= 0 % (every score floored to 0): the choice is the rule's default,
    and the warning says so instead of a standard error of a score that measured nothing."""
    worse = [_row(n, np.array([[1.2 + 0.1 * n]] * 12) / 12) for n in (2, 4)]
    assert all(r.score == 0.0 for r in worse)
    warned = ranking_warning(worse, n_samples=120)
    assert "better than their mean (every score 0 %)" in warned
    assert "not by measurement" in warned and "sysid sweep --validate" in warned
    fine = [_row(n, np.full((12, 1), 0.01 / 12)) for n in (2, 4)]
    assert ranking_warning(fine, n_samples=120) is None


def test_a_selection_whose_held_out_part_is_unlike_the_rest_says_nothing_was_ranked() -> None:
    """The plant's gain changes sign where the held-out part begins (the last 30 %), so every
    model of the grid simulates it worse than its mean (as every model of DaISy destill's 60
    samples of 8 channels did): the selection warns that nothing was ranked."""
    rng = np.random.default_rng(3)
    system = random_stable_system(n_states=3, n_inputs=1, n_outputs=2, rng=rng,
                                  radius=(0.5, 0.9))
    data = open_loop(system, n_samples=600, rng=rng, noise_std=0.05).data
    y = data.y.copy()
    y[420:] *= -1.0
    meth = get_method("iem")
    sel = select([[dataclasses.replace(data, y=y)]], method=meth, options=meth.options())
    assert sel.best.score == 0.0
    assert any("every score 0 %" in w for w in sel.warnings), sel.warnings
