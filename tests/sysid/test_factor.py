"""sysid/factor.py: the Gram matrix by lag correlations, the sample bound, the two factor routes."""
from __future__ import annotations

import numpy as np
import pytest

from sysid.data import IOData, block_hankel
from sysid.errors import DataError
from sysid.factor import build_products, min_samples, triangular_factor

RNG = np.random.default_rng(7)


def _flight(n: int, *, m: int = 2, ell: int = 2) -> IOData:
    return IOData(u=RNG.normal(size=(n, m)), y=RNG.normal(size=(n, ell)), dt=0.01)


def _w(products, flight: IOData) -> np.ndarray:
    return block_hankel(products.scaled_w(flight), block_rows=products.past + products.future)


def test_gram_by_lag_correlations_equals_w_w_transpose():
    flights = [_flight(90), _flight(61)]  # several flights: columns are added, never joined
    p = build_products(flights, past=4, future=3)
    w = np.hstack([_w(p, f) for f in flights])
    assert p.n_columns == w.shape[1] == (90 - 6) + (61 - 6)
    np.testing.assert_allclose(p.gram, w @ w.T, rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("n_flights", [1, 3])
def test_min_samples_is_the_exact_bound(n_flights):
    need = min_samples(past=3, future=2, n_channels=4, n_flights=n_flights)
    build_products([_flight(need) for _ in range(n_flights)], past=3, future=2)
    with pytest.raises(DataError, match=f"need at least {need} samples"):
        build_products([_flight(need - 1) for _ in range(n_flights)], past=3, future=2)


def test_qr_fallback_equals_cholesky_on_well_conditioned_data():
    p = build_products(_flight(400), past=3, future=3)
    order = np.r_[np.arange(12, 24), np.arange(12)]  # any symmetric permutation of the rows
    chol = triangular_factor(p, order, method="cholesky")
    qr = triangular_factor(p, order, method="qr")
    np.testing.assert_allclose(chol, qr, rtol=1e-8, atol=1e-8)
    w = np.hstack([_w(p, f) for f in p.flights])[order]
    np.testing.assert_allclose(chol @ chol.T, w @ w.T, rtol=1e-10, atol=1e-8)
    assert np.allclose(chol, np.tril(chol))


def test_rank_deficient_data_is_named():
    """A channel dependent on others at lag 0 is refused when the products are built, naming
    both channels (noise-free dynamics are not refused: tests/sysid/test_noise_free.py)."""
    u = RNG.normal(size=(300, 1))
    y = RNG.normal(size=(300, 1))
    data = IOData(u=u, y=np.hstack([y, 2.0 * y]), dt=0.01)  # a duplicated output channel
    with pytest.raises(DataError, match="rank deficient") as err:
        build_products(data, past=2, future=2)
    msg = str(err.value)
    assert "\n" not in msg and "output channel 1 ('y1')" in msg and "'y0'" in msg
