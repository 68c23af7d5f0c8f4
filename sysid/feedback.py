r"""Do the inputs depend on past outputs? A test for feedback in the data (closed loop).

In open loop the input is chosen without looking at the output: once its own past is known,
the past outputs tell nothing more about it. In closed loop (every flight: the onboard
controller computes the motor commands from the measured rates) they do. The test is Granger's:
for each input :math:`u_j` two least-squares regressions on the same rows,

.. math::

    u_j(k) = \sum_{i=1}^{L} a_i^T u(k-i) + e_r(k)
    \quad\text{and}\quad
    u_j(k) = \sum_{i=1}^{L} \left[ a_i^T u(k-i) + b_i^T y(k-i) \right] + e_f(k),

and the F statistic of the :math:`q = L \ell` added regressors,
:math:`F = \frac{(RSS_r - RSS_f) / q}{RSS_f / (N - L(m + \ell))}`, against
:math:`F(q, N - L(m + \ell))`. Feedback is found when the smallest p-value over the inputs is
below ``alpha / m`` (Bonferroni; ``alpha`` = 0.01). Lags from 1: an output at the same
sample is the plant's direct term as much as the controller's (MATLAB's ``feedback`` looks at
the same question through the impulse response from y to u).

What it is for: output error (``focus="simulation"``) and a direct term fitted on the logged
inputs are biased under feedback, and held-out data from the same loop reward the bias (on
closed-loop test systems the no-knobs choice took the simulation focus and its models fitted
the true plant 5-35 points worse than the prediction focus at the same settings). So
:func:`sysid.auto.select_plan` tries them only where this test finds no feedback.

Each flight's mean is removed and channels are scaled by one pooled standard deviation; rows
of all flights are pooled (each flight from its sample ``L`` on). An input its own past
predicts exactly (a deterministic multisine) leaves nothing for feedback to explain: p = 1.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from sysid.data import IOData

__all__ = ["ALPHA", "MAX_LAG", "FeedbackTest", "feedback_test"]

#: Significance of the test (over all inputs).
ALPHA = 0.01
#: Rows of the regression per regressor at least (fewer: the test cannot tell).
ROWS_PER_REGRESSOR = 5
#: Longest lag: long enough that a coloured or held input's own past explains what the
#: outputs' past would otherwise seem to add (with the data's memory, 6-18 samples, open-loop
#: PRBS, coloured and multisine inputs read as feedback).
MAX_LAG = 50


@dataclass(frozen=True)
class FeedbackTest:
    """Result of :func:`feedback_test`: ``p_values`` ``(m,)`` per input (NaN: not tested),
    ``lags`` :math:`L`, ``n_rows`` :math:`N`, ``feedback`` the verdict (None: too few rows
    to tell)."""

    p_values: np.ndarray
    input_names: tuple[str, ...]
    lags: int
    n_rows: int
    feedback: bool | None

    def describe(self) -> str:
        """One line for a report: ``"feedback: the inputs depend on past outputs (...)"``."""
        if self.feedback is None:
            return (f"feedback not tested: {self.n_rows} samples are too few for {self.lags} "
                    "lags")
        if self.feedback:
            return f"feedback: the inputs depend on past outputs ({self.evidence})"
        return f"no feedback found: past outputs do not predict the inputs ({self.evidence})"

    @property
    def evidence(self) -> str:
        """``"Granger test, u1: p = 3.7e-19, 10 lags"`` (the input most dependent)."""
        if np.isnan(self.p_values).all():
            return f"Granger test, {self.lags} lags: not enough samples"
        j = int(np.nanargmin(self.p_values))
        return (f"Granger test, {self.input_names[j]}: p = {self.p_values[j]:.2g}, "
                f"{self.lags} lags")


def feedback_test(flights: Sequence[IOData], *, lags: int | None = None,
                  alpha: float = ALPHA) -> FeedbackTest:
    """Granger's test for feedback from the outputs to the inputs (module docstring).
    ``lags`` :math:`L` (samples) defaults to :data:`MAX_LAG`, fewer on short records (2 times
    :data:`ROWS_PER_REGRESSOR` rows a regressor), at least 2."""
    first = flights[0]
    m, ell = first.n_inputs, first.n_outputs
    if lags is None:
        rows = sum(d.n_samples for d in flights)
        lags = max(2, min(MAX_LAG, rows // (2 * ROWS_PER_REGRESSOR * (m + ell))))
    us = [d.u - d.u.mean(axis=0) for d in flights if d.n_samples > lags]
    ys = [d.y - d.y.mean(axis=0) for d in flights if d.n_samples > lags]
    n_rows = sum(len(u) - lags for u in us)
    width = lags * (m + ell)
    names = tuple(first.input_names)
    if n_rows < ROWS_PER_REGRESSOR * width or not us:
        return FeedbackTest(p_values=np.full(m, np.nan), input_names=names, lags=lags,
                            n_rows=n_rows, feedback=None)
    su = np.sqrt(sum((u ** 2).sum(axis=0) for u in us) / sum(len(u) for u in us))
    sy = np.sqrt(sum((y ** 2).sum(axis=0) for y in ys) / sum(len(y) for y in ys))
    su[su == 0], sy[sy == 0] = 1.0, 1.0
    # regressors: lags of u first (the restricted model is their leading columns), then of y
    rows, targets = [], []
    for u, y in zip(us, ys, strict=True):
        u, y = u / su, y / sy
        n = len(u)
        rows.append(np.hstack([u[lags - i:n - i] for i in range(1, lags + 1)]
                              + [y[lags - i:n - i] for i in range(1, lags + 1)]))
        targets.append(u[lags:])
    x, t = np.vstack(rows), np.vstack(targets)
    r = np.linalg.qr(np.hstack([x, t]), mode="r")
    k_r, k_f = lags * m, width
    rss_r = (r[k_r:, width:] ** 2).sum(axis=0)  # (m,) residual sums, restricted
    rss_f = (r[k_f:, width:] ** 2).sum(axis=0)  # (m,) residual sums, full
    p = _f_sf(rss_r=rss_r, rss_f=rss_f, q=lags * ell, dof=n_rows - k_f)
    return FeedbackTest(p_values=p, input_names=names, lags=lags, n_rows=n_rows,
                        feedback=bool(np.nanmin(p) < alpha / m))


def _f_sf(*, rss_r: np.ndarray, rss_f: np.ndarray, q: int, dof: int) -> np.ndarray:
    """p-values of the F test of ``q`` added regressors on unit-variance inputs; 1 where an
    input is (numerically) a function of its own past."""
    import scipy.stats  # where used: scipy.stats takes 0.2 s to import

    exact = rss_r <= 1e-12 * (dof + q)
    f = (rss_r - rss_f) / q / np.maximum(rss_f / dof, 1e-300)
    return np.where(exact, 1.0, scipy.stats.f.sf(np.maximum(f, 0.0), q, dof))
