"""``sysid.identify``: no knobs from arrays, as ``sysid identify`` chooses."""

from __future__ import annotations

import numpy as np
import pytest

import sysid
from sysid.auto import select
from sysid.methods import get_method
from tests.sysid.systems import random_stable_system


def _open_loop(seed: int, n: int = 1500) -> tuple[sysid.IOData, sysid.IOData]:
    """A 3-state SISO plant with a direct term under white input, 20 dB output noise; the
    noise-free continuation validates."""
    rng = np.random.default_rng(seed)
    system = random_stable_system(n_states=3, n_inputs=1, n_outputs=1, rng=rng,
                                  radius=(0.5, 0.9))
    system = system.replace(D=np.array([[0.8]]))
    u = rng.standard_normal((n + 1000, 1))
    clean = system.simulate(u)
    y = clean + 0.1 * clean[:n].std() * rng.standard_normal(clean.shape)
    return (sysid.IOData(u=u[:n], y=y[:n], dt=0.1),
            sysid.IOData(u=u[n:], y=clean[n:], dt=0.1))


def test_identify_chooses_everything_not_given() -> None:
    ident, val = _open_loop(7)
    sel = sysid.identify(ident)
    model = sel.model
    assert model.provenance["feedthrough"]  # no feedback in the data: D tried and kept
    assert sel.feedback is not None and sel.feedback.feedback is False
    assert sel.method_note and sel.focus_note and sel.feedthrough_note
    assert float(np.mean(sysid.compare(model, val, x0="estimate", warn=False).fit)) > 97.0
    # the same choice as the selection the command line runs
    iem = get_method("iem")
    same = select([[ident]], method=iem, options=iem.options(), choose_focus=True,
                  choose_feedthrough="open-loop", choose_method=True)
    assert (same.best.past, same.best.future, same.best.order) == (
        sel.best.past, sel.best.future, sel.best.order)
    np.testing.assert_allclose(same.model.A, model.A)


def test_given_settings_are_kept() -> None:
    ident, _ = _open_loop(8)
    sel = sysid.identify(ident, method="iem", focus="prediction", feedthrough=False,
                         orders=[3], pasts=[10], futures=[8])
    prov = sel.model.provenance
    assert (prov["method"], prov["focus"], prov["feedthrough"]) == ("iem", "prediction", False)
    assert (sel.best.past, sel.best.future, sel.best.order) == (10, 8, 3)
    assert sel.method_note == "" and sel.feedthrough_note == ""


@pytest.mark.parametrize(("bad", "message"), [
    ([], "no data given"), ("data.csv", "data is a str"), (5, "data is a int"),
    ([np.zeros((10, 2))], r"data\[0\] is a ndarray; wrap arrays in sysid.IOData")])
def test_bad_data_is_one_line(bad, message) -> None:
    """The checks every method makes on its data (``sysid.data.as_flights``)."""
    with pytest.raises(sysid.DataError, match=message):
        sysid.identify(bad)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"validation": "x"}, "data is a str"),
    ({"orders": []}, "orders: pass at least one value"),
    ({"workers": 0}, "workers=0"),
])
def test_bad_keywords_are_one_line(kwargs, message) -> None:
    ident, _ = _open_loop(9, n=300)
    with pytest.raises(sysid.SysIdError, match=message):
        sysid.identify(ident, **kwargs)


def test_validation_with_other_channels_is_refused_before_the_grid_runs() -> None:
    ident, _ = _open_loop(9, n=300)
    other = sysid.IOData(u=np.zeros((200, 2)), y=np.zeros((200, 1)), dt=0.1)
    with pytest.raises(sysid.DimensionError, match="validation records' channels differ"):
        sysid.identify(ident, validation=other)
