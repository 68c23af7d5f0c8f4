"""The predictor's memory (VARX lag by AICc) that scales the default horizons."""

from __future__ import annotations

import numpy as np
import scipy.signal

import sysid
from sysid.memory import MAX_LAG, predictor_memory
from tests.sysid.systems import random_stable_system


def _arx(*, a: list[float], b: list[float], n: int, seed: int, dt: float = 1.0,
         noise_std: float = 0.1) -> sysid.IOData:
    """``y(k) = -a1 y(k-1) - ... + b1 u(k-1) + ... + e(k)``, white u and e: an ARX model whose
    one-step predictor needs exactly ``max(len(a), len(b))`` past samples."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    e = noise_std * rng.standard_normal(n)
    y = scipy.signal.lfilter([0.0, *b], [1.0, *a], u) + scipy.signal.lfilter([1.0], [1.0, *a], e)
    return sysid.IOData(u=u[:, None], y=y[:, None], dt=dt)


def test_a_known_arx_process_has_its_own_lag_at_any_sample_time() -> None:
    a = [-1.5, 0.7, -0.1]  # poles 0.28, 0.5, 0.72
    b = [1.0, 0.5, 0.25]
    lags = [predictor_memory([_arx(a=a, b=b, n=4000, seed=s)]).lag for s in range(5)]
    assert all(3 <= lag <= 5 for lag in lags), lags  # never short of the true lag of 3
    assert sum(lag == 3 for lag in lags) >= 3, lags
    slow = _arx(a=a, b=b, n=4000, seed=0, dt=0.001)
    assert predictor_memory([slow]).lag == lags[0]  # samples, not seconds


def test_a_moving_average_noise_needs_more_memory_than_white_noise() -> None:
    """An ARMAX process has an infinitely long predictor, and the lag grows with what the
    data support: a noise zero at -0.9 needs far more past than the same plant as ARX."""
    rng = np.random.default_rng(3)
    n = 5000
    u = rng.standard_normal(n)
    e = 0.5 * rng.standard_normal(n)
    plant = scipy.signal.lfilter([0.0, 1.0], [1.0, -0.8], u)
    arx = scipy.signal.lfilter([1.0], [1.0, -0.8], e)  # A y = B u + e: one lag
    white = predictor_memory([sysid.IOData(u=u[:, None], y=(plant + arx)[:, None],
                                           dt=1.0)]).lag
    ma = scipy.signal.lfilter([1.0, 0.9], [1.0, -0.8], e)  # (1 + 0.9 q^-1) / (1 - 0.8 q^-1)
    colored = predictor_memory([sysid.IOData(u=u[:, None], y=(plant + ma)[:, None],
                                             dt=1.0)]).lag
    assert white <= 2 and colored >= 3 * white + 3, (white, colored)


def test_short_records_and_dead_channels_bound_the_search() -> None:
    short = _arx(a=[-0.5], b=[1.0], n=60, seed=1)
    mem = predictor_memory([short])
    assert mem.max_lag < 12 and mem.aicc.shape == (mem.max_lag + 1,)  # 5 rows a regressor
    assert 1 <= mem.lag <= mem.max_lag
    long = _arx(a=[-0.5], b=[1.0], n=20_000, seed=1)
    assert predictor_memory([long]).max_lag == MAX_LAG
    # a constant output (a sensor that did not move) is left out, not a zero determinant
    d = _arx(a=[-1.2, 0.35], b=[1.0], n=3000, seed=2)
    dead = sysid.IOData(u=d.u, y=np.hstack([d.y, np.zeros_like(d.y)]), dt=1.0)
    assert predictor_memory([dead]).lag == predictor_memory([d]).lag
    # several flights: the regression stacks them, each from its own start
    parts = [sysid.IOData(u=d.u[i:i + 1000], y=d.y[i:i + 1000], dt=1.0) for i in (0, 1000, 2000)]
    assert abs(predictor_memory(parts).lag - predictor_memory([d]).lag) <= 1


def test_flights_share_one_model_offsets_and_flat_experiments_do_not_move_the_lag() -> None:
    """The pooled VARX must hold in every flight: one scale for all of them (a flight with a
    low-passed input scaled on its own changed the fitted gain and gave lag 3-4 for an ARX(1)),
    one intercept a flight (an offset of 0.2 output std gave lags 19-37 without it), and a
    flat experiment too short to take part does not remove an output from the others."""
    rng = np.random.default_rng(7)
    n = 3000

    def flight(u: np.ndarray) -> sysid.IOData:
        e = 0.3 * rng.standard_normal(n)
        y = scipy.signal.lfilter([0.0, 1.0], [1.0, -0.7], u) \
            + scipy.signal.lfilter([1.0], [1.0, -0.7], e)
        return sysid.IOData(u=u[:, None], y=y[:, None], dt=1.0)

    white = flight(rng.standard_normal(n))
    lowpassed = flight(scipy.signal.lfilter([0.2], [1.0, -0.8], rng.standard_normal(n)))
    assert predictor_memory([white, lowpassed]).lag <= 2
    shifted = sysid.IOData(u=white.u, y=white.y + 0.2 * float(white.y.std()), dt=1.0)
    assert predictor_memory([shifted]).lag == predictor_memory([white]).lag <= 2
    flat = sysid.IOData(u=np.zeros((10, 1)), y=np.zeros((10, 1)), dt=1.0)
    with_flat = predictor_memory([white, flat])
    assert with_flat.lag == predictor_memory([white]).lag and with_flat.n_rows > 0


def test_noise_free_data_have_the_memory_of_their_state_not_of_rounding() -> None:
    """Noise-free outputs of a system with more states than outputs: the lag-1 residual is
    exactly zero in some directions of the outputs but not in all, and rounding is all that
    is left from the observability index on. The memory is that index (one more for the
    means removed in place of an intercept); a zero determinant once stopped the search at
    lag 1 (order 3 at most, a 84 % model of a fourth-order system) and rounding noise scored
    as memory gave lags 10-50 at random."""
    lags = []
    for seed in range(4):
        rng = np.random.default_rng(seed)
        system = random_stable_system(n_states=4, n_inputs=2, n_outputs=3, rng=rng, dt=1.0)
        u = rng.standard_normal((1000, 2))
        lags.append(predictor_memory([sysid.IOData(u=u, y=system.simulate(u), dt=1.0)]).lag)
    assert all(2 <= lag <= 3 for lag in lags), lags  # observability index 2
    rng = np.random.default_rng(5)
    siso = random_stable_system(n_states=3, n_inputs=1, n_outputs=1, rng=rng, dt=1.0)
    u = rng.standard_normal((2000, 1))
    assert 3 <= predictor_memory([sysid.IOData(u=u, y=siso.simulate(u), dt=1.0)]).lag <= 4


def test_an_exactly_explained_output_does_not_end_the_search_for_the_others() -> None:
    """A logged output that is an exact filter of the inputs (a delayed copy of the command)
    beside a noisy ARX(3) output: the copy is explained from lag 1 on, the other output
    still needs 3 lags."""
    d = _arx(a=[-1.5, 0.7, -0.1], b=[1.0, 0.5, 0.25], n=4000, seed=4)
    copy = np.concatenate([[0.0], d.u[:-1, 0]])[:, None]  # y2(k) = u(k-1)
    both = sysid.IOData(u=d.u, y=np.hstack([d.y, copy]), dt=1.0)
    assert 3 <= predictor_memory([both]).lag <= 5
