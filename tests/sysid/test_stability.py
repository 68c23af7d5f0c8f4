"""sysid.stability: what "auto", "enforce" and "free" do to the poles of an identified A."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from sysid.errors import ParameterError
from sysid.stability import MARGINAL_RADIUS, NEAR_BAND, STABILITY_MODES, check_stability, stabilize


def _radii(a: np.ndarray) -> np.ndarray:
    return np.sort(np.abs(np.linalg.eigvals(a)))


def test_stabilize_modes():
    a = np.diag([1.008, 0.5, 1.3])
    a_auto, moved = stabilize(a, mode="auto")
    radii = np.sort(np.abs(np.linalg.eigvals(a_auto)))
    np.testing.assert_allclose(radii, [0.5, MARGINAL_RADIUS, 1.3])  # 1.3 is a real instability
    assert len(moved) == 1 and abs(moved[0][0]) == pytest.approx(1.008)
    a_enf, moved = stabilize(a, mode="enforce")
    radii = np.sort(np.abs(np.linalg.eigvals(a_enf)))
    np.testing.assert_allclose(radii, [0.5, 1 / 1.3, 1 / 1.008])  # reflected
    assert len(moved) == 2
    a_free, moved = stabilize(a, mode="free")
    assert a_free is a and not moved
    # a complex pair moves as a pair, keeping its angle: near z = 1 (an integrator's estimate)
    # onto MARGINAL_RADIUS, an oscillation further round the circle reflected (damped, not
    # ringing forever)
    for angle, radius in ((0.03, MARGINAL_RADIUS), (0.3, 1 / 1.02)):
        rot = 1.02 * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        lam = np.linalg.eigvals(stabilize(rot, mode="auto")[0])
        np.testing.assert_allclose(np.abs(lam), radius)
        np.testing.assert_allclose(np.sort(np.abs(np.angle(lam))), [angle, angle])
    near_minus_one = stabilize(np.diag([-1.05, 0.5]), mode="auto")[0]
    np.testing.assert_allclose(_radii(near_minus_one), [0.5, 1 / 1.05])


def test_auto_moves_exactly_the_near_band(caplog):
    """``1 < |z| <= 1 + NEAR_BAND`` is noise around an integrator and moves; further out is a
    real instability, kept with one warning that names the radius."""
    inside = np.diag([1.0 + NEAR_BAND, 0.5])
    assert _radii(stabilize(inside, mode="auto")[0])[-1] == pytest.approx(MARGINAL_RADIUS)
    outside = np.diag([1.0 + NEAR_BAND + 1e-3, 0.5])
    with caplog.at_level(logging.WARNING, logger="sysid.stability"):
        kept, moved = stabilize(outside, mode="auto")
    assert kept is outside and not moved
    assert [r.getMessage()[:24] for r in caplog.records] == ["pole at |z| = 1.101 kept"]


def test_two_poles_moved_onto_one_radius_stay_two_modes():
    """1.0024 and 1.0725 (a no-knobs closed-loop model of a plant with one pole at 0.999) both
    move onto 0.999. Scaling the Schur form's blocks kept their coupling and made a Jordan
    block: a double integrator, the model's DC gain 4.6 times the plant's. Moved in the
    eigenbasis they stay two modes (0.999 twice, two eigenvectors), every eigenvector kept."""
    a = np.array([[1.0024, 0.02, 0.2], [0.0, 1.0725, 0.3], [0.0, 0.0, 0.78]])
    moved_a, moved = stabilize(a, mode="auto")
    assert len(moved) == 2
    np.testing.assert_allclose(_radii(moved_a), [0.78, MARGINAL_RADIUS, MARGINAL_RADIUS])
    # geometric multiplicity 2: A' - 0.999 I has rank 1, not 2 (a Jordan block)
    sv = np.linalg.svd(moved_a - MARGINAL_RADIUS * np.eye(3), compute_uv=False)
    assert sv[1] < 1e-9 * sv[0], sv
    _, vec = np.linalg.eig(a)
    for v in vec.T:  # each of A's eigenvectors is one of A''s
        w = moved_a @ v
        assert np.linalg.norm(w - (v @ w) / (v @ v) * v) < 1e-9


def test_a_chain_the_data_show_keeps_its_coupling():
    """Rate and angle (a double integrator, dt 2 ms) estimated at 1.0004 and 1.0001, their
    eigenvectors nearly parallel: one chain, kept one (moved in the eigenbasis the angle forgot
    the rate: 5e-14 after 1 s from a unit rate, against 1.13 before the move; review)."""
    a = np.array([[1.0004, 0.0], [0.002, 1.0001]])
    moved_a, moved = stabilize(a, mode="auto")
    assert len(moved) == 2
    np.testing.assert_allclose(_radii(moved_a), [MARGINAL_RADIUS, MARGINAL_RADIUS])
    angle = np.linalg.matrix_power(moved_a, 500) @ [1.0, 0.0]
    assert angle[1] > 0.5, angle  # the angle still integrates the rate


def test_stable_poles_are_left_alone_in_any_basis():
    """The move is made on A's real Schur form, so in a rotated basis too only the moved pole
    changes: the others keep their values to rounding, and an A with nothing to move is
    returned as it is."""
    rng = np.random.default_rng(0)
    q, _ = np.linalg.qr(rng.normal(size=(4, 4)))
    blocks = np.zeros((4, 4))
    blocks[:2, :2] = [[0.3, -0.4], [0.4, 0.3]]  # 0.3 ± 0.4j
    blocks[2, 2], blocks[3, 3] = 1.05, -0.6
    a = q @ blocks @ q.T
    new, moved = stabilize(a, mode="auto")
    after = np.sort_complex(np.linalg.eigvals(new))
    np.testing.assert_allclose(after, np.sort_complex([0.3 - 0.4j, 0.3 + 0.4j, MARGINAL_RADIUS,
                                                       -0.6]), atol=1e-12)
    assert moved == [pytest.approx((1.05 + 0j, MARGINAL_RADIUS + 0j))]
    stable = q @ np.diag([0.9, 0.5, -0.2, 0.1]) @ q.T
    for mode in STABILITY_MODES:
        same, none = stabilize(stable, mode=mode)
        assert same is stable and none == []


def test_enforce_pulls_the_unit_circle_and_the_band_above_it_in():
    """``enforce``: a pole on the circle or just inside MARGINAL_RADIUS's band goes to
    MARGINAL_RADIUS; one outside is reflected (1/|z|) unless that lands above the cap."""
    a = np.diag([1.0, 0.9995, 2.0, 0.5])
    new, moved = stabilize(a, mode="enforce")
    np.testing.assert_allclose(_radii(new), [0.5, 0.5, MARGINAL_RADIUS, MARGINAL_RADIUS])
    assert len(moved) == 3
    assert max(abs(np.linalg.eigvals(new))) < 1.0


@pytest.mark.parametrize("mode", ["strict", "", None, "Auto"])
def test_unknown_modes_are_refused_in_one_line(mode):
    with pytest.raises(ParameterError, match=r"use one of \('auto', 'enforce', 'free'\)"):
        check_stability(mode)
    with pytest.raises(ParameterError):
        stabilize(np.eye(2), mode=mode)


def test_the_warning_for_a_pole_kept_outside_does_not_guess_its_cause(caplog):
    """Order 18 on a 4-state system put poles at 1.99 and 1.18: an over-fitted model, not an
    unstable plant. The warning names both causes and both remedies."""
    with caplog.at_level(logging.WARNING, logger="sysid.stability"):
        stabilize(np.diag([1.99, 1.18, 0.5]), mode="auto")
    messages = [r.getMessage() for r in caplog.records]
    assert len(messages) == 2 and messages[0].startswith("pole at |z| = 1.990 kept")
    for msg in messages:
        assert "genuinely" not in msg and "\n" not in msg
        for words in ("unstable", "more states than the data support", "lower order",
                      "stability='enforce'"):
            assert words in msg, msg
