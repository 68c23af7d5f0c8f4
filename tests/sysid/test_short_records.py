"""No knobs on short records: the default grid reaches the order of the data's memory."""

from __future__ import annotations

import numpy as np
import pytest

import sysid
from sysid.auto import default_grid, holdout, max_blocks, select
from sysid.methods import get_method
from tests.sysid.systems import random_stable_system


def _short(seed: int, *, n_samples: int, n_states: int, n_inputs: int = 1, n_outputs: int = 1
           ) -> tuple[sysid.IOData, sysid.IOData]:
    """``n_samples`` of a random system under white input at 20 dB (white output noise of a
    tenth of the output's spread) and 2000 noise-free samples after them to validate on."""
    rng = np.random.default_rng(seed)
    system = random_stable_system(n_states=n_states, n_inputs=n_inputs, n_outputs=n_outputs,
                                  rng=rng, radius=(0.5, 0.95))
    u = rng.standard_normal((n_samples + 2000, n_inputs))
    clean = system.simulate(u)
    y = clean + 0.1 * clean[:n_samples].std(axis=0) * rng.standard_normal(clean.shape)
    return (sysid.IOData(u=u[:n_samples], y=y[:n_samples], dt=system.dt),
            sysid.IOData(u=u[n_samples:], y=clean[n_samples:], dt=system.dt))


def _truth(model: sysid.StateSpaceModel, val: sysid.IOData) -> float:
    return float(np.mean(sysid.compare(model, val, x0="estimate", warn=False).fit))


def test_sixty_samples_of_a_third_order_system_reach_its_order() -> None:
    """60 samples (42 identify) of third-order SISO systems at 20 dB: three Hankel columns
    per row allowed futures of 2 only, so orders of 1, and the no-knobs models fitted the
    noise-free output -11 to 80 % (median 4 %) where order 3 with past = future = 4..6
    fits 95-98 %. The future the memory's order needs (memory 3 samples: future 4) now joins
    the grid with fewer columns per row; the other pairs keep three. Eight systems: 86-98 %
    (median 94 %)."""
    iem = get_method("iem")
    fits, reach = [], []
    for seed in range(8):
        ident, val = _short(seed, n_samples=60, n_states=3)
        sel = select([[ident]], method=iem, options=iem.options(), choose_focus=True)
        fits.append(_truth(sel.model, val))
        reach.append(sel.grid["orders"][-1])
        part = holdout([[ident]])[0]
        *rest, last = sel.grid["futures"]
        assert sel.grid["pasts"][-1] + max(rest, default=last) <= max(max_blocks(part), 4)
        assert sel.grid["pasts"][-1] + last <= max_blocks(part, columns_per_row=1.0)
    assert sum(r >= 3 for r in reach) >= 6, reach
    assert min(fits) > 80.0 and np.median(fits) > 90.0, np.round(fits, 1)


def test_many_outputs_on_a_short_record() -> None:
    """2 inputs, 30 outputs, 300 samples (210 identify): three Hankel columns per row hold
    no past 2, future 2, and no knobs (even with the order given) refused with "need about
    384" although past 3, future 3, order 4 identify it well. Past 2, future 2 with fewer
    columns per row now form the grid; too short a record says to give the horizons."""
    ident, val = _short(52, n_samples=300, n_states=4, n_inputs=2, n_outputs=30)
    iem = get_method("iem")
    for orders in (None, [4]):
        sel = select([[ident]], method=iem, options=iem.options(), orders=orders,
                     choose_focus=True)
        assert sel.best.order == 4 and _truth(sel.model, val) > 90.0
    short = sysid.IOData(u=ident.u[:120], y=ident.y[:120], dt=ident.dt)
    with pytest.raises(sysid.DataError, match=r"need about 131.*--past/--future/--order"):
        default_grid([short])
