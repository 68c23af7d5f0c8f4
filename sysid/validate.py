"""Model validation that means something for a quadrotor (issue 3 item 7; thesis section 4.4).

Motor command to angular rate is close to an integrator, so pure simulation of a whole flight
drifts even for a good model. :func:`compare` therefore offers, like MATLAB ``compare``:

* **simulation** ``horizon=None``: :math:`x(k+1) = A x(k) + B u(k)`,
  :math:`\\hat y(k) = C x(k) + D u(k)` from an initial state estimated by least squares, over the
  whole record or, with ``window`` (seconds), over consecutive windows each with its own
  :math:`x_0`. With the forced response :math:`y_f` (zero initial state) and the extended
  observability matrix :math:`\\mathcal O_L = [C; CA; \\dots; CA^{L-1}]` (the thesis'
  :math:`\\Gamma_L`, section 3.1.1),

  .. math:: \\hat x_0 = \\arg\\min_{x_0} \\sum_{i=1}^{l} \\frac{1}{s_i^2}
     \\| (y - y_f)_i - (\\mathcal O_L x_0)_i \\|_2^2 ,

  each output channel :math:`i` weighted by its standard deviation :math:`s_i` over the record,
  as the fit counts it (unweighted, a gyro in deg/s with a spread of 140 decided the initial
  state alone and the accelerometers in g, spread 0.06, were simulated from whatever it left
  them: -2254 % where the model reaches 52 % on the demo's validation flight).

* **k-step-ahead prediction** ``horizon=k``: the predictor form of the innovation model
  (thesis eq. 3.18, with :math:`A_K = A - KC`, :math:`B_K = B - KD` as in eq. 3.23)

  .. math:: \\hat x(j+1) = (A - KC)\\,\\hat x(j) + (B - KD)\\,u(j) + K\\,y(j)

  gives :math:`\\hat x(j|j-1)`; from :math:`\\hat x(t-k+1|t-k)` the model is run open-loop for
  :math:`k-1` steps to :math:`\\hat y(t|t-k) = C\\hat x(t|t-k) + D u(t)`. ``horizon=1`` is the
  one-step predictor; a horizon longer than the record is simulation. The first :math:`k-1`
  samples (no measurement old enough) are simulated from :math:`\\hat x_0`.

The fit is MATLAB's NRMSE fit, per channel:
:math:`100\\,(1 - \\|y - \\hat y\\| / \\|y - \\bar y\\|)`.

Models whose predictor :math:`A - KC` is unstable are flagged (``predictor_stable``) and logged;
:func:`sysid.kalman.stable_predictor` returns the model with the steady-state Kalman gain,
which makes :math:`A - KC` stable whenever :math:`(A, C)` is detectable.
"""

from __future__ import annotations

import itertools
import logging
import math
import warnings
from collections.abc import Sequence
from numbers import Real

import numpy as np

from sysid.comparison import CompareResult
from sysid.data import IOData, as_flights
from sysid.errors import DataError, DimensionError, HorizonError
from sysid.model import StateSpaceModel

__all__ = [
    "INTEGRATING_RADIUS",
    "MIN_WINDOW_SAMPLES",
    "SIMULATION_WINDOW_S",
    "CompareResult",
    "below_mean_warning",
    "channel_weights",
    "compare",
    "default_window",
    "estimate_x0",
    "fit_percent",
    "min_fit_samples",
    "observability_matrix",
    "predict",
    "simulate_windows",
    "simulation_window",
    "split_windows",
]

#: Simulation window (s) for near-integrating models: long enough to show the dynamics, short
#: enough that an integrator's drift from the initial state does not decide the fit.
SIMULATION_WINDOW_S = 2.0
#: ... but never fewer samples than this (slowly sampled data: dt = 1 s makes 2 s two samples).
MIN_WINDOW_SAMPLES = 20
#: ... and at least this many output values per state of the initial state fitted on each
#: window (12 states on 20 samples of one output fit any window: every score near 100 %).
SAMPLES_PER_STATE = 10


def min_fit_samples(*, n_states: int = 0, n_outputs: int = 1) -> int:
    """Fewest samples a fit with its own initial state means something on (a simulation
    window, or a whole record): :data:`MIN_WINDOW_SAMPLES`, and :data:`SAMPLES_PER_STATE`
    output values per initial-state parameter (``n_states`` fitted on ``n_outputs``
    channels). Fewer, and the initial state alone fits the samples: every score near 100 %."""
    return max(MIN_WINDOW_SAMPLES, math.ceil(SAMPLES_PER_STATE * n_states / max(n_outputs, 1)))


def simulation_window(*, dt: float, n_samples: int | None = None, n_states: int = 0,
                      n_outputs: int = 1, samples: int | None = None) -> float:
    """Seconds of the default simulation window: :data:`SIMULATION_WINDOW_S` (or ``samples``
    samples, when given), at least :func:`min_fit_samples` samples of ``dt``
    (:data:`MIN_WINDOW_SAMPLES`, and :data:`SAMPLES_PER_STATE` output values per
    initial-state parameter: ``n_states`` fitted on ``n_outputs`` channels each window), at
    most the record (``n_samples``, if known)."""
    base = round(SIMULATION_WINDOW_S / dt) if samples is None else samples
    samples = max(base, min_fit_samples(n_states=n_states, n_outputs=n_outputs))
    return (samples if n_samples is None else min(samples, n_samples)) * dt


#: A model with a pole at least this far out integrates over any validation window: simulating
#: a whole record through it measures only its drift (or growth).
INTEGRATING_RADIUS = 0.995


def default_window(model: StateSpaceModel, *, n_samples: int | None = None) -> float | None:
    """Seconds of the simulation windows of a fit whose mode nobody chose, the one rule of
    ``sysid compare``'s default, ``identify``'s fit tables (identification and --validate
    data) and the cost line of ``stability=``: :func:`simulation_window` sized for the model
    (2 s; longer for many states) and capped by ``n_samples`` (the shortest record), when the
    model has a pole at ``|z| >= INTEGRATING_RADIUS``; None otherwise (each record simulated
    whole)."""
    if float(np.max(np.abs(model.poles()), initial=0.0)) < INTEGRATING_RADIUS:
        return None
    return simulation_window(dt=model.dt, n_samples=n_samples, n_states=model.n_states,
                             n_outputs=model.n_outputs)


log = logging.getLogger(__name__)

#: Rows of the observability matrix growing beyond this factor (unstable A) are left out of
#: the initial-state fit: they carry no usable information and overflow.
_MAX_GROWTH = 1e8

def fit_percent(y_true: np.ndarray, y_sim: np.ndarray) -> np.ndarray:
    """NRMSE fit per channel, percent: ``100 (1 - ||y - yhat|| / ||y - mean(y)||)``, shape (l,).

    ``y_true`` and ``y_sim`` are (N, l) (1-D is one channel). 100 is a perfect fit, 0 is no
    better than the mean, negative is worse. A constant channel of ``y_true`` gets NaN.
    """
    y = np.asarray(y_true, dtype=float)
    yh = np.asarray(y_sim, dtype=float)
    if y.ndim == 1:
        y = y[:, None]
    if yh.ndim == 1:
        yh = yh[:, None]
    if y.shape != yh.shape:
        raise DimensionError(f"y_true {y.shape} and y_sim {yh.shape} differ; pass equal shapes")
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        err = np.linalg.norm(y - yh, axis=0)
        spread = np.linalg.norm(y - y.mean(axis=0), axis=0)
        fit = 100.0 * (1.0 - err / spread)
    fit[spread == 0] = np.nan
    fit[~np.isfinite(err)] = -np.inf
    return fit


def observability_matrix(*, A: np.ndarray, C: np.ndarray, length: int) -> np.ndarray:
    """Extended observability matrix ``[C; CA; ...; CA^(L-1)]`` stacked as (L, l, n).

    Built by doubling (``log2 L`` matrix products), so long records cost no Python loop, and
    only the ``L`` rows asked for are formed (no ``(L, n, n)`` stack of the powers of A).
    """
    obs = np.array(C, dtype=float)[None]  # C A^0 .. C A^(k-1), (k, l, n)
    step = np.asarray(A, dtype=float)  # A^k
    while obs.shape[0] < length:
        obs = np.concatenate([obs, obs[:length - obs.shape[0]] @ step], axis=0)
        step = step @ step
    return obs[:length]


#: Runs at least this long go through the modal filters (:func:`_run_states_modal`).
_MODAL_MIN_LENGTH = 64


def _run_states(*, A: np.ndarray, Bu: np.ndarray, x0: np.ndarray) -> np.ndarray:
    """States x(0..L-1) of ``x(k+1) = A x(k) + Bu[..., k, :]`` for a batch.

    ``Bu`` is (W, L, n) (already multiplied input), ``x0`` (W, n); returns (W, L, n). Long
    runs use :func:`_run_states_modal` (no Python loop over the samples) when A is safely
    diagonalisable.
    """
    w, length, n = Bu.shape
    if length >= _MODAL_MIN_LENGTH and n:
        x = _run_states_modal(A=A, Bu=Bu, x0=x0)
        if x is not None:
            return x
    x = np.empty((w, length, n))
    cur = np.array(x0, dtype=float)
    at = A.T
    for k in range(length):
        x[:, k] = cur
        cur = cur @ at + Bu[:, k]
    return x


def _run_states_modal(*, A: np.ndarray, Bu: np.ndarray, x0: np.ndarray) -> np.ndarray | None:
    """:func:`_run_states` in the modal basis ``A = V diag(lambda) V^{-1}``: each mode is a
    first-order recursion ``z(k+1) = lambda z(k) + b(k)``, run by ``scipy.signal.lfilter``
    over the whole batch at once. None when ``cond(V) > 1e8`` (defective or nearly so)."""
    import scipy.signal  # where used: scipy.signal takes 0.5 s to import

    lam, vec = np.linalg.eig(A)
    if not np.all(np.isfinite(lam)) or np.linalg.cond(vec) > 1e8:
        return None
    vinv = np.linalg.inv(vec)
    # z(0) = V^-1 x0, z(k) = lambda z(k-1) + b(k-1): one filter over [z(0), b(0..L-2)]
    src = np.concatenate([(np.asarray(x0, dtype=float) @ vinv.T)[:, None, :],
                          Bu[:, :-1] @ vinv.T], axis=1)  # (W, L, n)
    z = np.empty(src.shape, dtype=complex)
    with np.errstate(over="ignore", invalid="ignore"):
        for i, li in enumerate(lam):
            z[:, :, i] = scipy.signal.lfilter([1.0], [1.0, -li], src[:, :, i], axis=1)
        return (z @ vec.T).real


def split_windows(n_samples: int, window: int) -> list[slice]:
    """Consecutive windows of ``window`` samples; the remainder joins the last window."""
    if window >= n_samples:
        return [slice(0, n_samples)]
    starts = list(range(0, n_samples - window + 1, window))
    bounds = [*starts, n_samples]
    return [slice(a, b) for a, b in itertools.pairwise(bounds)]


def channel_weights(y: np.ndarray) -> np.ndarray:
    """``(l,)`` weights of the initial-state fit for the record ``y`` (N, l): one over each
    channel's standard deviation (module docstring). A constant or non-finite channel gets the
    weight of the most spread one, so it neither dominates nor vanishes."""
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # an all-NaN channel: no spread
        spread = np.nanstd(np.asarray(y, dtype=float), axis=0)
    ok = np.isfinite(spread) & (spread > 0)
    if not ok.any():
        return np.ones(spread.shape)
    return 1.0 / np.where(ok, spread, spread[ok].max())


def estimate_x0(
    *, A: np.ndarray, C: np.ndarray, residual: np.ndarray, weights: np.ndarray | None = None
) -> np.ndarray:
    """Least-squares initial state(s) explaining ``residual = y - y_forced``.

    ``residual`` is (L, l) or a batch (W, L, l); returns (n,) or (W, n). ``weights`` (l,)
    multiplies each output channel's errors (:func:`channel_weights`; none: every channel
    alike, in its own units). Uses :func:`observability_matrix` and one least-squares solve for
    the whole batch.
    """
    r = np.asarray(residual, dtype=float)
    single = r.ndim == 2
    if single:
        r = r[None]
    with np.errstate(over="ignore", invalid="ignore"):
        obs = observability_matrix(A=A, C=C, length=r.shape[1])  # (L, l, n)
    x0 = _x0_given_obs(obs=obs, A=A, C=C, residual=r, weights=weights)
    return x0[0] if single else x0


def _x0_given_obs(*, obs: np.ndarray, A: np.ndarray, C: np.ndarray, residual: np.ndarray,
                  weights: np.ndarray | None) -> np.ndarray:
    """:func:`estimate_x0` of a batch ``residual`` (W, L, l) with its observability matrix
    ``obs`` (L, l, n) already built; returns (W, n)."""
    r = residual
    w = r.shape[0]
    with np.errstate(over="ignore", invalid="ignore"):
        # An unstable A makes late rows explode: keep the samples where all is finite and sane
        # (max |obs| without a copy of obs: it is (L, l, n), a whole record's on long ones).
        size = np.maximum(obs.max(axis=(1, 2), initial=0.0), -obs.min(axis=(1, 2), initial=0.0))
    usable = np.isfinite(size) & (size <= _MAX_GROWTH * max(np.abs(C).max(initial=0.0), 1.0))
    usable &= np.isfinite(r).all(axis=(0, 2))
    if not usable.any() or A.shape[0] == 0:  # no state (a static model): nothing to fit
        return np.zeros((w, A.shape[0]))
    scale = np.ones(C.shape[0]) if weights is None else np.asarray(weights, dtype=float)
    if scale.shape != (C.shape[0],):
        raise DimensionError(f"weights has shape {scale.shape}; pass ({C.shape[0]},), one per "
                             "output channel")
    obs_k = ((obs if usable.all() else obs[usable]) * scale[:, None]).reshape(-1, A.shape[0])
    rhs = (r[:, usable] * scale).reshape(w, -1).T
    x0, *_ = np.linalg.lstsq(obs_k, rhs, rcond=None)
    return x0.T


def simulate_windows(
    model: StateSpaceModel, *, u: np.ndarray, y: np.ndarray, window: int | None = None,
    x0: str | np.ndarray = "estimate", weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate ``model`` over ``u`` (N, m), whole or in windows of ``window`` samples.

    Each window starts from its own least-squares initial state fitted to ``y`` (N, l), its
    channels weighted by ``weights`` (l,) (default: :func:`channel_weights` of the whole
    record; :func:`compare` passes those of all its records) (``x0="estimate"``), from zero
    (``"zero"``), or, without windows, from a given (n,) state.
    Returns ``(y_sim (N, l), x0s (W, n))``.
    """
    A, B, C, D = _matrices(model)
    n_samples, n = u.shape[0], A.shape[0]
    slices = split_windows(n_samples, window or n_samples)
    weights = channel_weights(y) if weights is None else weights
    y_sim = np.empty((n_samples, C.shape[0]))
    x0s = np.zeros((len(slices), n))
    if not isinstance(x0, str):
        if window is not None:
            raise DataError("a given x0 needs window=None; use x0='estimate' with windows")
        x0s[0] = _as_state(x0, n)
    # Windows of equal length run as one batch: at most two lengths (the last may be longer).
    for length in sorted({sl.stop - sl.start for sl in slices}):
        idx = [i for i, sl in enumerate(slices) if sl.stop - sl.start == length]
        uw = np.stack([u[slices[i]] for i in idx])  # (W, L, m)
        yw = np.stack([y[slices[i]] for i in idx])
        states = _run_states(A=A, Bu=uw @ B.T, x0=np.zeros((len(idx), n)))
        y_forced = states @ C.T + uw @ D.T
        with np.errstate(over="ignore", invalid="ignore"):
            obs = observability_matrix(A=A, C=C, length=length)  # (L, l, n), built once
        if isinstance(x0, str) and x0 == "estimate":
            x0s[idx] = _x0_given_obs(obs=obs, A=A, C=C, residual=yw - y_forced,
                                     weights=weights)
        free = np.einsum("kln,wn->wkl", obs, x0s[idx])
        for j, i in enumerate(idx):
            y_sim[slices[i]] = y_forced[j] + free[j]
    return y_sim, x0s


def predict(
    model: StateSpaceModel, *, u: np.ndarray, y: np.ndarray, horizon: int,
    x0: str | np.ndarray = "estimate", weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``horizon``-step-ahead prediction of ``y`` (N, l) from ``u`` (N, m) (module docstring).

    Returns ``(y_pred (N, l), x0 (n,))``; ``x0="estimate"`` fits the predictor's initial state
    by least squares on the one-step prediction errors, channels weighted by ``weights`` (l,)
    (default :func:`channel_weights` of ``y``).
    """
    A, B, C, D = _matrices(model)
    K = model.K
    n_samples, n = u.shape[0], A.shape[0]
    _check_steps(horizon)
    ak = A - K @ C
    bu = u @ (B - K @ D).T + y @ K.T  # predictor input term, (N, n)
    forced = _run_states(A=ak, Bu=bu[None], x0=np.zeros((1, n)))[0]
    if isinstance(x0, str):
        if x0 == "estimate":
            x0v = estimate_x0(A=ak, C=C, residual=y - forced @ C.T - u @ D.T,
                              weights=channel_weights(y) if weights is None else weights)
        else:
            x0v = np.zeros(n)
    else:
        x0v = _as_state(x0, n)
    # One-step predicted states x(j|j-1), (N, n): the predictor run again, from x0 (the forced
    # part plus the free response of x0, without an (N, n, n) stack of powers of A_K)
    xh = _run_states(A=ak, Bu=bu[None], x0=x0v[None])[0] if x0v.any() else forced
    h = min(horizon, n_samples)
    y_pred = np.empty((n_samples, C.shape[0]))
    if h > 1:  # samples with no measurement h steps back: simulation from x0
        xs = _run_states(A=A, Bu=(u[: h - 1] @ B.T)[None], x0=x0v[None])[0]
        y_pred[: h - 1] = xs @ C.T + u[: h - 1] @ D.T
    z = xh[: n_samples - h + 1]
    for i in range(1, h):
        z = z @ A.T + u[i - 1 : n_samples - h + i] @ B.T
    y_pred[h - 1 :] = z @ C.T + u[h - 1 :] @ D.T
    return y_pred, x0v


def _check_steps(horizon: object) -> None:
    if isinstance(horizon, bool) or not isinstance(horizon, int | np.integer) or horizon < 1:
        raise HorizonError(f"horizon = {horizon!r}; pass a positive whole number of steps "
                           "(or None for simulation)")


def _as_state(x0: object, n: int) -> np.ndarray:
    arr = np.asarray(x0, dtype=float).reshape(-1)
    if arr.shape != (n,):
        raise DimensionError(f"x0 has {arr.size} entries; pass {n} (the model order) or 'estimate'")
    return arr


def _matrices(model: StateSpaceModel) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    return model.A, model.B, model.C, model.D


def compare(
    model: StateSpaceModel,
    data: IOData | Sequence[IOData],
    *,
    horizon: int | None = None,
    x0: str | np.ndarray = "estimate",
    window: float | None = None,
    warn: bool = True,
) -> CompareResult:
    """Compare ``model`` with measured data: simulation or ``horizon``-step prediction.

    ``data`` is one IOData or a list (each experiment its own initial state). ``window``
    (seconds) splits each record into consecutive windows simulated from their own estimated
    initial state (simulation only). ``x0`` is ``"estimate"`` (least squares), ``"zero"`` or an
    (n,) state (single experiment, no windows). ``warn=False`` skips the logged warning for an
    unstable predictor (the flag is set either way). Returns a :class:`CompareResult`.
    """
    flights = as_flights(data)
    A, B, C, _ = _matrices(model)
    if (flights[0].n_inputs, flights[0].n_outputs) != (B.shape[1], C.shape[0]):
        raise DimensionError(
            f"model has {B.shape[1]} inputs/{C.shape[0]} outputs but data has "
            f"{flights[0].n_inputs}/{flights[0].n_outputs}; select the matching channels"
        )
    if isinstance(x0, str) and x0 not in ("estimate", "zero"):
        raise DataError(f"x0 = {x0!r}; use 'estimate', 'zero' or an array of the model order")
    if not isinstance(x0, str) and len(flights) > 1:
        raise DataError("a given x0 fits one experiment; pass one IOData or x0='estimate'")
    if horizon is not None and window is not None:
        raise HorizonError("window applies to simulation; pass either horizon or window")
    if horizon is not None:
        _check_steps(horizon)
    dt = flights[0].dt
    if abs(dt - model.dt) > 1e-6 * model.dt:
        raise DataError(f"data sampled at dt={dt} s but the model has dt={model.dt} s; "
                        "resample the data to the model's rate (sysid.zoh_resample)")
    win = None
    if window is not None:
        if isinstance(window, bool) or not isinstance(window, Real) or not 0 < window < np.inf:
            raise HorizonError(f"window={window!r}; pass the window in seconds (finite, > 0)")
        win = round(window / dt)
        if win < 1 or win * C.shape[0] < A.shape[0]:
            raise HorizonError(
                f"window {window} s is {win} samples, too short to estimate {A.shape[0]} states "
                f"from {C.shape[0]} outputs; use window >= {-(-A.shape[0] // C.shape[0]) * dt} s"
            )
    model_stable = model.is_stable
    pred_stable = model.predictor_is_stable
    if warn and horizon is not None and not pred_stable:
        log.warning("predictor A - KC is unstable (max |eig| >= 1); "
                    "predictions may diverge: use sysid.stable_predictor(model)")
    outs, x0s = [], []
    weights = channel_weights(np.vstack([d.y for d in flights]))  # as the fit counts them
    for d in flights:
        with np.errstate(over="ignore", invalid="ignore"):
            if horizon is None:
                yh, xs = simulate_windows(model, u=d.u, y=d.y, window=win, x0=x0,
                                          weights=weights)
            else:
                yh, xv = predict(model, u=d.u, y=d.y, horizon=int(horizon), x0=x0,
                                 weights=weights)
                xs = xv[None]
        outs.append(yh)
        x0s.append(xs)
    fits = np.array([fit_percent(d.y, yh) for d, yh in zip(flights, outs, strict=True)])
    fit = fit_percent(np.vstack([d.y for d in flights]), np.vstack(outs))
    diverged = not all(np.isfinite(o).all() for o in outs)
    names = tuple(model.output_names)
    return CompareResult(
        fit=fit, fits=fits, y_model=tuple(outs), y_measured=tuple(d.y for d in flights),
        x0=tuple(x0s), horizon=horizon, window=win, model_stable=model_stable,
        predictor_stable=pred_stable, diverged=diverged, output_names=names,
    )


def below_mean_warning(results: Sequence[tuple[str, CompareResult]], *, data: str
                       ) -> str | None:
    """One line naming every channel whose fit on ``data`` (the sessions' names) is below 0 %
    in any of ``results`` (``(mode label, result)``: the overall fit of each), what that
    means and what to try; None when every fit is 0 % or more (a constant channel's NaN is
    no fit, not a bad one). For the commands that print validation fits (``sysid identify
    --validate``, ``sysid compare``) to log once per run."""
    bad = []
    for label, res in results:
        for name, fit in zip(res.output_names, np.asarray(res.fit, dtype=float), strict=True):
            if fit < 0:  # NaN is not
                shown = f"{fit:.1f} %" if np.isfinite(fit) else "diverged"
                bad.append(f"{name} {shown} ({label})")
    if not bad:
        return None
    return (f"fit below 0 % on {data}: {', '.join(bad)}: the model reproduces these channels "
            "worse than a constant at their mean would; try one-step or k-step prediction "
            "(sysid compare --horizon K) for near-integrating closed-loop rate dynamics, more "
            "excitation, a lower --order, or validation on a flight of the same kind")
