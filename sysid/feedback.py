r"""Do the inputs depend on past outputs? A test for feedback in the data (closed loop).

In open loop the input is chosen without looking at the output, so it is independent of the
output's *disturbance* (the part of the output the inputs do not explain) at every lag. In
closed loop (every flight: the onboard controller computes the motor commands from the
measured rates) the controller feeds the disturbance back. The test is Granger's, run on the
disturbance instead of the outputs, in two least-squares steps on pooled rows:

1. the disturbance: a high-order ARX model of the outputs (all of them at once),
   :math:`y(k) = \sum_{i=1}^{L} A_i y(k-i) + \sum_{i=0}^{L} B_i u(k-i) + \varepsilon(k)`;
   its residuals :math:`\varepsilon` estimate the innovations (consistent in open and closed
   loop as the order grows; the past of :math:`u` and :math:`\varepsilon` spans the same as
   the past of :math:`u` and :math:`y`);
2. for each input :math:`u_j`, its own past (restricted) against its own past and the
   disturbance's (full),

   .. math::

       u_j(k) = \sum_{i=1}^{L} a_i^T u(k-i) + e_r(k)
       \quad\text{and}\quad
       u_j(k) = \sum_{i=1}^{L} a_i^T u(k-i) + \sum_{i=1}^{L_\varepsilon} b_i^T
       \varepsilon(k-i) + e_f(k),
       \qquad L_\varepsilon = \lceil L / 2 \rceil,

   and the Wald statistic of the :math:`q = L_\varepsilon \ell` added coefficients with a
   heteroscedasticity-consistent covariance (HC3: each row's squared residual over
   :math:`(1 - h_k)^2`, :math:`h_k` its leverage), :math:`W / q` against
   :math:`F(q, N - Lm - q)`.

Why the disturbance: Granger's test on the outputs themselves compares with the input's own
past of :math:`L` lags, and the outputs carry the plant's memory of the input beyond them;
whenever :math:`L` lags do not whiten the input (coloured, narrow-band, held PRBS: a spectrum
with zeros, whose own-past predictor converges slowly), the outputs' past "predicts" the input
in open loop (old test, :math:`L` = 50: PRBS held 10-50 samples p = 6e-5 to 3e-153, DaISy
flutter 2e-25 and cstr 4e-9). The disturbance carries no memory of the input, so the input's
colour does not matter. Why HC3: held inputs change only at some samples, and the residuals
of a plant the ARX model does not fit exactly (nonlinear, noise-free: DaISy cstr) are largest
at the same samples; the plain F test's equal-variance assumption then reads that as feedback
(cstr p = 4e-16 by F, 0.09 by HC3).

Feedback is found when an input's p-value is below ``alpha / m`` (Bonferroni; ``alpha`` =
0.01) **and** the disturbance's past explains at least :data:`MIN_SHARE` of that input's
variance: an input its own past predicts to within a few parts in :math:`10^{11}` (DaISy
flutter, a smooth, heavily oversampled excitation: p = 3e-7 for 4e-12 of its variance) has no
room for a feedback that could bias anything. An input its own past predicts exactly (a
deterministic multisine), or outputs the inputs explain exactly (no disturbance), give p = 1.
Lags from 1: an output at the same sample is the plant's direct term as much as the
controller's. Its purpose:

output error (``focus="simulation"``) and a direct term fitted on the logged inputs are biased
under feedback, and held-out data from the same loop reward the bias (on closed-loop test
systems the no-knobs choice took the simulation focus and its models fitted the true plant
5-35 points worse than the prediction focus at the same settings). So
:func:`sysid.auto.select_plan` tries them only where this test finds no feedback.

Each flight's mean is removed and channels are scaled by one pooled standard deviation; rows
of all flights are pooled (each flight from its sample :math:`2L` on); each regression uses at
most :data:`MAX_ROWS` of them (a random subset, seed 0; the residuals of step 1 are computed
on every row).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData

__all__ = ["ALPHA", "MAX_LAG", "MIN_SHARE", "FeedbackTest", "feedback_test"]

#: Significance of the test (over all inputs).
ALPHA = 0.01
#: Rows of each regression per regressor at least (fewer: the test cannot tell).
ROWS_PER_REGRESSOR = 5
#: Longest lag L (ARX order and the input's own past): long enough for the plant's memory
#: in the disturbance's model.
MAX_LAG = 50
#: Rows each regression uses at most (a random subset, seed 0, of longer records: the test
#: has power to spare there, and its run time stays a small part of a no-knobs run).
MAX_ROWS = 40_000
#: Least share of an input's variance the disturbance's past must explain for feedback
#: (0.1 % of its rms): below, a feedback cannot bias a fit measurably.
MIN_SHARE = 1e-6
#: Rows of the ARX regressors formed at a time for the disturbance's residuals (memory).
ARX_BLOCK = 65_536


@dataclass(frozen=True)
class FeedbackTest:
    """Result of :func:`feedback_test`: ``p_values`` ``(m,)`` per input (NaN: not tested),
    ``lags`` :math:`L`, ``n_rows`` :math:`N`, ``feedback`` the verdict (None: too few rows
    to tell), ``shares`` ``(m,)`` the share of each input's variance the disturbance's past
    explains beyond the input's own past."""

    p_values: np.ndarray
    input_names: tuple[str, ...]
    lags: int
    n_rows: int
    feedback: bool | None
    shares: np.ndarray | None = None

    def describe(self) -> str:
        """One line for a report: ``"feedback: the inputs depend on past outputs (...)"``."""
        if self.feedback is None:
            return (f"feedback not tested: {self.n_rows} samples are too few for {self.lags} "
                    "lags")
        if self.feedback:
            return f"feedback: the inputs depend on past outputs ({self.evidence})"
        if self.shares is not None and np.nanmin(self.p_values) < ALPHA / len(self.p_values):
            return (f"no feedback that matters: past outputs explain less than "
                    f"{_percent(MIN_SHARE)} of any input's variance ({self.evidence})")
        return f"no feedback found: past outputs do not predict the inputs ({self.evidence})"

    @property
    def evidence(self) -> str:
        """``"Granger test on the disturbance, u1: p = 3.7e-19 (2.1 % of its variance), 10
        lags"`` (the input most dependent)."""
        if np.isnan(self.p_values).all():
            return f"Granger test on the disturbance, {self.lags} lags: not enough samples"
        j = int(np.nanargmin(self.p_values))
        share = "" if self.shares is None else f" ({_percent(self.shares[j])} of its variance)"
        return (f"Granger test on the disturbance, {self.input_names[j]}: "
                f"p = {self.p_values[j]:.2g}{share}, {self.lags} lags")


def _percent(share: float) -> str:
    return f"{100 * share:.2g} %"


def feedback_test(flights: Sequence[IOData], *, lags: int | None = None,
                  alpha: float = ALPHA) -> FeedbackTest:
    """Granger's test for feedback from the outputs' disturbance to the inputs (module
    docstring). ``lags`` :math:`L` (samples: the ARX order and the input's own past; the
    disturbance's past is :math:`\\lceil L/2 \\rceil`) defaults to :data:`MAX_LAG`, fewer on
    short records (2 times :data:`ROWS_PER_REGRESSOR` rows a regressor), at least 2."""
    first = flights[0]
    m, ell = first.n_inputs, first.n_outputs
    if lags is None:
        rows = sum(d.n_samples for d in flights)
        lags = max(2, min(MAX_LAG, rows // (2 * ROWS_PER_REGRESSOR * (m + ell))))
    lead = (lags + 1) // 2
    names = tuple(first.input_names)
    us = [d.u - d.u.mean(axis=0) for d in flights if d.n_samples > 2 * lags]
    ys = [d.y - d.y.mean(axis=0) for d in flights if d.n_samples > 2 * lags]
    n_rows = sum(len(u) - 2 * lags for u in us)
    arx_width = lags * ell + (lags + 1) * m
    if (not us or n_rows < ROWS_PER_REGRESSOR * (lags * m + lead * ell)
            or n_rows + lags * len(us) < ROWS_PER_REGRESSOR * arx_width):
        return FeedbackTest(p_values=np.full(m, np.nan), input_names=names, lags=lags,
                            n_rows=n_rows, feedback=None)
    su = np.sqrt(sum((u ** 2).sum(axis=0) for u in us) / sum(len(u) for u in us))
    sy = np.sqrt(sum((y ** 2).sum(axis=0) for y in ys) / sum(len(y) for y in ys))
    su[su == 0], sy[sy == 0] = 1.0, 1.0
    us, ys = [u / su for u in us], [y / sy for y in ys]
    eps = _disturbance(us, ys, lags)
    if eps is None:  # the inputs explain the outputs exactly: nothing to feed back
        return FeedbackTest(p_values=np.ones(m), input_names=names, lags=lags,
                            n_rows=n_rows, feedback=False, shares=np.zeros(m))
    target = np.vstack([u[2 * lags:] for u in us])
    rows = _subset(len(target))
    u_past = _lagged_rows([u[lags:] for u in us], range(1, lags + 1), lags, rows)
    e_past = _lagged_rows(eps, range(1, lead + 1), lags, rows)
    p, share = _added_regressors(u_past, e_past, target[rows])
    found = (p < alpha / m) & (share >= MIN_SHARE)
    return FeedbackTest(p_values=p, input_names=names, lags=lags, n_rows=n_rows,
                        feedback=bool(found.any()), shares=share)


def _subset(n: int) -> slice | np.ndarray:
    """All ``n`` rows, or :data:`MAX_ROWS` of them drawn at random (seed 0), in order."""
    if n <= MAX_ROWS:
        return slice(None)
    return np.sort(np.random.default_rng(0).choice(n, MAX_ROWS, replace=False))


def _lagged(x: np.ndarray, lags: range, start: int, stop: int | None = None) -> np.ndarray:
    """Columns ``x(k - i)`` for ``i`` in ``lags``, rows ``k = start .. stop - 1`` (``stop``:
    ``len(x)``)."""
    stop = len(x) if stop is None else stop
    return np.hstack([x[start - i:stop - i] for i in lags])


def _lagged_rows(xs: Sequence[np.ndarray], lags: range, start: int,
                 rows: slice | np.ndarray) -> np.ndarray:
    """``np.vstack([_lagged(x, lags, start) for x in xs])[rows]`` without the pooled matrix
    (``rows``: :func:`_subset`, sorted), which on long records is the largest array of an
    identification (101 columns of 1.4e6 rows: 1.1 GB)."""
    if isinstance(rows, slice):
        return np.vstack([_lagged(x, lags, start) for x in xs])[rows]
    offsets = np.cumsum([0, *(len(x) - start for x in xs)])
    out = np.empty((len(rows), len(lags) * xs[0].shape[1]))
    for f, x in enumerate(xs):
        lo, hi = np.searchsorted(rows, offsets[f:f + 2])
        k = rows[lo:hi] - offsets[f] + start  # rows of this flight, as samples of x
        out[lo:hi] = np.hstack([x[k - i] for i in lags])
    return out


def _disturbance(us: list[np.ndarray], ys: list[np.ndarray], lags: int
                 ) -> list[np.ndarray] | None:
    """Per flight the residuals (from sample ``lags`` on) of the ARX model of all outputs on
    ``lags`` past outputs and inputs ``0..lags``, each channel scaled to unit variance;
    channels the inputs explain exactly (relative std below 1e-6) are left out, None when
    all are."""
    t = np.vstack([y[lags:] for y in ys])
    rows = _subset(len(t))
    x = np.hstack([_lagged_rows(ys, range(1, lags + 1), lags, rows),
                   _lagged_rows(us, range(0, lags + 1), lags, rows)])
    r = np.linalg.qr(np.hstack([x, t[rows]]), mode="r")
    k = x.shape[1]
    theta = np.linalg.lstsq(r[:k, :k], r[:k, k:], rcond=None)[0]
    del x
    # every row's residual, the regressors built a block of rows at a time (memory)
    resid = np.empty_like(t)
    row = 0
    for u, y in zip(us, ys, strict=True):
        for a in range(lags, len(y), ARX_BLOCK):
            b = min(a + ARX_BLOCK, len(y))
            x = np.hstack([_lagged(y, range(1, lags + 1), a, b),
                           _lagged(u, range(0, lags + 1), a, b)])
            resid[row:row + b - a] = t[row:row + b - a] - x @ theta
            row += b - a
    scale = resid.std(axis=0)
    keep = scale > 1e-6 * t.std(axis=0)
    if not keep.any():
        return None
    resid = resid[:, keep] / scale[keep]
    return np.split(resid, np.cumsum([len(y) - lags for y in ys])[:-1])


def _added_regressors(base: np.ndarray, added: np.ndarray, target: np.ndarray
                      ) -> tuple[np.ndarray, np.ndarray]:
    """p-values of the HC3 Wald test (F form) of ``added`` beyond ``base`` for each target
    column, and the share of its variance they explain; p = 1 for a target ``base``
    predicts exactly."""
    import scipy.stats  # where used: scipy.stats takes 0.2 s to import

    n, k_base = base.shape
    q_b, _ = np.linalg.qr(base)
    added = added - q_b @ (q_b.T @ added)
    target_r = target - q_b @ (q_b.T @ target)
    q_a, _ = np.linalg.qr(added)
    leverage = np.minimum((q_b ** 2).sum(axis=1) + (q_a ** 2).sum(axis=1), 0.99)
    del q_b
    q = added.shape[1]
    dof = n - k_base - q
    coef = q_a.T @ target_r  # (q, m) in the orthonormal coordinates of the added columns
    rss_r = (target_r ** 2).sum(axis=0)
    tss = (target ** 2).sum(axis=0)
    p = np.ones(target.shape[1])
    for j in range(target.shape[1]):
        if rss_r[j] <= 1e-12 * tss[j]:
            continue  # the input's own past predicts it exactly
        resid = target_r[:, j] - q_a @ coef[:, j]
        weights = resid ** 2 / (1.0 - leverage) ** 2
        cov = (q_a * weights[:, None]).T @ q_a
        wald = float(coef[:, j] @ np.linalg.lstsq(cov, coef[:, j], rcond=None)[0])
        p[j] = scipy.stats.f.sf(max(wald, 0.0) / q, q, dof)
    share = np.where(p < 1.0, (coef ** 2).sum(axis=0) / np.maximum(tss, 1e-300), 0.0)
    return p, share
