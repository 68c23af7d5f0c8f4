"""Input directions that barely move: four motor commands excited along roll only (a roll-only
flight) are named with the direction that does not move (yaw); a three-axis excitation, one
input, and inputs of very different units are not."""

from __future__ import annotations

import numpy as np

import sysid
from sysid.quirks import data_warnings, direction_warnings, find_weak_directions
from tests.sysid.systems import random_stable_system

# the quad-X mixer's columns: thrust, roll, pitch, yaw -> motors m1..m4
MIX = np.array([[1.0, -1.0, -1.0, -1.0], [1.0, -1.0, 1.0, 1.0],
                [1.0, 1.0, 1.0, -1.0], [1.0, 1.0, -1.0, 1.0]])
MOTORS = [f"motor.m{i}" for i in range(1, 5)]


def _motors(axis_sd: tuple[float, float, float, float], *, n: int = 3000,
            seed: int = 0) -> np.ndarray:
    """Motor commands (n, 4) from thrust, roll, pitch, yaw with these spreads."""
    rng = np.random.default_rng(seed)
    axes = rng.normal(size=(n, 4)) * np.asarray(axis_sd)
    return 40000.0 + axes @ MIX.T


def _data(u: np.ndarray, *, seed: int = 0) -> sysid.IOData:
    rng = np.random.default_rng(seed)
    y = rng.normal(size=(u.shape[0], 2))
    return sysid.IOData(u=u, y=y, dt=0.02, input_names=MOTORS[:u.shape[1]])


def test_a_roll_only_excitation_names_the_yaw_direction_of_the_motors() -> None:
    u = _motors((300.0, 1000.0, 150.0, 20.0))  # roll excited; yaw moves 2 % of it
    [weak] = find_weak_directions([_data(u)])
    assert weak.ratio < 0.05
    signs = dict((name, np.sign(w)) for name, w in weak.weights)
    assert signs["motor.m1"] == signs["motor.m3"] == -signs["motor.m2"] == -signs["motor.m4"]
    [line] = direction_warnings([_data(u)])
    assert line.startswith("the 4 moving inputs move along 3 independent directions: ")
    assert "+motor.m1 -motor.m2 +motor.m3 -motor.m4 (0.0" in line and "barely moves" in line


def test_a_three_axis_excitation_one_input_or_units_apart_are_not_named() -> None:
    assert not find_weak_directions([_data(_motors((300.0, 1000.0, 900.0, 800.0)))])
    assert not find_weak_directions([_data(_motors((0.0, 1000.0, 0.0, 0.0))[:, :1])])
    u = np.random.default_rng(3).normal(size=(2000, 2)) * [1e-3, 1e4]  # units never decide
    assert not find_weak_directions([_data(u)])


def test_an_input_that_does_not_move_is_not_counted_as_a_direction() -> None:
    """[a, b, a + b + noise, constant]: 3 moving inputs along 2 directions (review: "4 inputs
    along 3 of 4")."""
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(2, 2000))
    u = np.column_stack([a, b, a + b + 0.01 * rng.normal(size=2000), np.full(2000, 3.0)])
    [line] = direction_warnings([_data(u)])
    assert line.startswith("the 3 moving inputs move along 2 independent directions: ")


def test_two_inputs_that_move_together_are_a_warning_of_the_selection() -> None:
    """A known system driven by two inputs that are one signal (the second 0.5 times the
    first, plus 1 % of independent noise): the no-knobs selection says so."""
    rng = np.random.default_rng(4)
    system = random_stable_system(n_states=2, n_inputs=2, n_outputs=1, rng=rng,
                                  radius=(0.5, 0.8))
    first = rng.normal(size=(3000, 1))
    u = np.hstack([first, 0.5 * first + 0.005 * rng.normal(size=(3000, 1))])
    y = system.simulate(u) + 0.05 * rng.normal(size=(3000, 1))
    data = sysid.IOData(u=u, y=y, dt=system.dt)
    assert any("the 2 moving inputs move along 1 independent direction: " in w
               for w in data_warnings([data]))
    assert any("move along 1 independent direction: " in w
               for w in sysid.identify(data).warnings)
