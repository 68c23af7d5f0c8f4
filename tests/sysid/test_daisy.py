"""Public open-loop benchmark data (DaISy) under the protocol of benchmarks.md (issue 10).

The two fastest sets stay in the suite; ``python -m bench daisy`` runs all six beside SIPPY.
Floors sit a little under the figures reached (measured 2026-11-27): dryer 77.87 (SIPPY's best
77.05; 78.35 until the prediction focus's B, D came from the one-step error), heating_system
63.12 (SIPPY's best 64.01, PARSIM-P).
"""

from __future__ import annotations

import numpy as np
import pytest

import sysid

from .daisy import DAISY, best_model, load, protocol_fit

pytestmark = pytest.mark.skipif(not DAISY.is_dir(), reason="shared DaISy sets not present")


@pytest.mark.parametrize(("name", "floor"), [("dryer", 77.5), ("heating_system", 62.5)])
def test_best_model_on_daisy_sets(name, floor):
    fit, label, order, per = best_model(name)
    assert fit >= floor, (label, order, per)
    assert 2 <= order <= 10


@pytest.mark.parametrize(("name", "floor"), [("dryer", 76.5), ("heating_system", 56.5)])
def test_po_moesp_default_simulates_on_daisy_sets(name, floor):
    """PO-MOESP with output-error B, D: never below 0 %, and far above eq. 3.15 where the
    input is colored (heating_system: 46.0 with the thesis' B, D)."""
    ident, val = load(name)
    fits = []
    for n in range(2, 11):
        fit = protocol_fit(sysid.po_moesp(ident, order=n, past=20, future=20), val)
        if np.isfinite(fit):
            assert fit > 0.0, (n, fit)
            fits.append(fit)
    assert max(fits) >= floor, fits


@pytest.mark.parametrize(("name", "floor"), [("dryer", 74.0), ("heating_system", 54.0)])
def test_no_knobs_selection_on_daisy_sets(name, floor):
    """What a new user gets without horizons or order (``sysid identify``'s selection, IEM,
    focus chosen on held-out data) is near the best of the protocol's sweep: measured dryer
    76.6-76.7 and heating_system 58.0-58.1 (IEM without / with D). The grid was in seconds of
    quadrotor flight and gave past 1, future 2, order 1 here: 33.8 and -43.5 %."""
    from sysid.auto import select
    from sysid.methods import get_method

    ident, val = load(name)
    iem = get_method("iem")
    sel = select([[ident]], method=iem, options=iem.options(), choose_focus=True)
    assert sel.best.past >= 3 and sel.best.order >= 2, sel.grid
    assert protocol_fit(sel.model, val) >= floor, (sel.best, sel.grid)


def test_other_sets_load_by_the_same_protocol(tmp_path, monkeypatch):
    """``python -m bench daisy`` runs the protocol on other sets' files
    (``BENCH_DAISY_EXTRA``): columns 1-based, means removed, first 2/3 identify."""
    from . import daisy

    table = np.column_stack([np.arange(1.0, 31.0), np.arange(30.0) ** 2, -np.arange(30.0)])
    np.savetxt(tmp_path / "set.dat", table)
    extra = daisy.parse_extra(f" mine={tmp_path / 'set.dat'}:2:1,3 ; ")
    assert extra == {"mine": (tmp_path / "set.dat", [2], [1, 3])}
    monkeypatch.setattr(daisy, "EXTRA", extra)
    ident, val = daisy.load("mine")
    assert (ident.n_samples, val.n_samples, ident.n_inputs, ident.n_outputs) == (20, 10, 1, 2)
    np.testing.assert_allclose(ident.y[0], [1.0 - 15.5, 0.0 + 14.5])
    np.testing.assert_allclose(ident.u[:, 0] + 0.0, table[:20, 1] - table[:, 1].mean())
    for bad in ("mine=set.dat:2", "mine=set.dat:0:1", "set.dat:1:2", "mine=set.dat:a:1"):
        with pytest.raises(ValueError, match="1-based"):
            daisy.parse_extra(bad)
