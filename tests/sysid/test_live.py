"""Live identification (sysid.live): the incremental Gram equals the offline products and the
live model equals the offline IEM model of the same samples."""

from __future__ import annotations

import os

import numpy as np
import pytest

from sysid import IOData, detrend_data, iem
from sysid.errors import DataError, DimensionError
from sysid.factor import build_products
from sysid.live import CHILD_NICENESS, LiveIdentifier, LiveIdentifierProcess
from tests.sysid.systems import closed_loop, pbsid_example1


def _experiment(n: int = 1500) -> IOData:
    exp = closed_loop(pbsid_example1(dt=0.02), n_samples=n, rng=np.random.default_rng(3))
    d = exp.data
    # an operating point far from zero, as in flight (hover PWM, 1 g)
    return IOData(u=d.u + np.array([3.0e4, -2.0]), y=d.y + np.array([1.0, 250.0]), dt=d.dt)


def _feed(live: LiveIdentifier, data: IOData, *, rng: np.random.Generator) -> None:
    start = 0
    while start < data.n_samples:
        k = int(rng.integers(1, 90))
        live.append(u=data.u[start:start + k], y=data.y[start:start + k])
        start += k


def _sorted_poles(p: np.ndarray) -> np.ndarray:
    return p[np.lexsort((p.imag, p.real))]


def test_incremental_gram_equals_offline_products() -> None:
    data = _experiment()
    live = LiveIdentifier(n_inputs=2, n_outputs=2, order=4, past=10, future=5, dt=data.dt)
    _feed(live, data, rng=np.random.default_rng(0))
    offline = build_products(detrend_data(data, kind="mean")[0], past=10, future=5)
    got = live.products()
    assert got.n_columns == offline.n_columns
    np.testing.assert_allclose(got.u_scale, offline.u_scale, rtol=1e-10)
    np.testing.assert_allclose(got.gram, offline.gram, rtol=1e-8, atol=1e-8 * offline.n_columns)


def test_live_model_equals_offline_iem_after_every_update() -> None:
    data = _experiment()
    live = LiveIdentifier(n_inputs=2, n_outputs=2, order=4, past=10, future=5, dt=data.dt)
    rng = np.random.default_rng(1)
    for stop in (400, 900, data.n_samples):
        start = live.n_samples
        live.append(u=data.u[start:stop], y=data.y[start:stop])
        upd = live.update()
        part = detrend_data(IOData(u=data.u[:stop], y=data.y[:stop], dt=data.dt),
                            kind="mean")[0]
        ref = iem(part, order=4, past=10, future=5)
        np.testing.assert_allclose(_sorted_poles(upd.poles), _sorted_poles(ref.poles()),
                                   atol=1e-8)
        np.testing.assert_allclose(upd.model.C @ upd.model.B, ref.C @ ref.B, rtol=1e-6,
                                   atol=1e-9)
        assert upd.n_samples == stop
    del rng
    # and the true system is found: the poles of PBSID example 1
    truth = _sorted_poles(pbsid_example1(dt=0.02).poles())
    np.testing.assert_allclose(_sorted_poles(upd.poles), truth, atol=0.05)


def test_too_few_samples_and_bad_rows_are_errors() -> None:
    live = LiveIdentifier(n_inputs=2, n_outputs=2, order=4, past=10, future=5, dt=0.02)
    live.append(u=np.ones((5, 2)), y=np.ones((5, 2)))
    with pytest.raises(DataError, match="too few"):
        live.update()
    with pytest.raises(DimensionError, match="expected"):
        live.append(u=np.ones((3, 3)), y=np.ones((3, 2)))
    with pytest.raises(DataError, match="non-finite"):
        live.append(u=np.full((1, 2), np.nan), y=np.ones((1, 2)))


def test_constant_channels_are_named() -> None:
    """On a locked vehicle every motor stayed 0: "a channel is constant so far" named none."""
    live = LiveIdentifier(n_inputs=2, n_outputs=1, order=2, past=5, future=5, dt=0.02,
                          input_names=("motor.m1", "motor.m2"), output_names=("gyro.x",))
    rng = np.random.default_rng(0)
    live.append(u=np.zeros((200, 2)), y=rng.standard_normal((200, 1)))
    with pytest.raises(DataError, match=r"constant so far: motor\.m1, motor\.m2; excite it"):
        live.update()


@pytest.mark.skipif(not hasattr(os, "getpriority"), reason="POSIX process priorities")
def test_the_child_process_identifies_alike_at_a_lower_cpu_priority() -> None:
    """The engine in its own interpreter gives the same model, and runs nicer than the flight
    (a real-time firmware in the loop beside it must not be starved)."""
    data = _experiment()
    settings = {"n_inputs": 2, "n_outputs": 2, "order": 4, "past": 10, "future": 5,
                "dt": data.dt}
    child, here = LiveIdentifierProcess(**settings), LiveIdentifier(**settings)
    try:
        for live in (child, here):
            live.append(u=data.u, y=data.y)
        remote = child.update()
        nice = os.getpriority(os.PRIO_PROCESS, child._proc.pid)
    finally:
        child.close()
    assert nice == min(19, os.getpriority(os.PRIO_PROCESS, 0) + CHILD_NICENESS)
    np.testing.assert_allclose(_sorted_poles(remote.poles), _sorted_poles(here.update().poles),
                               atol=1e-12)
    assert child._proc.returncode == 0
