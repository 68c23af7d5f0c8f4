"""The innovation covariance of an identified model: that of its own one-step prediction errors.

Every identified model's ``noise_cov`` ``(l, l)`` is

.. math::

    \\hat\\Sigma = \\frac1N \\sum_t e(t) e(t)^T, \\qquad e(t) = y(t) - \\hat y(t|t-1),

the one-step prediction errors of the *final* model (after the stability step, the focus' B, D
and PEM) on the identification data, each flight from its own least-squares initial state
(:func:`sysid.kalman.one_step_errors`, what ``sysid resid`` analyses), ``N`` the samples of
all flights. It is the covariance that goes with the model's K: a Kalman filter
``x(k+1|k) = A x + B u + K (y - C x - D u)`` built from the model has these innovations, and
``(A, C, K, noise_cov)`` is the noise description :func:`sysid.stable_predictor` and a state
estimator take. MATLAB's System Identification Toolbox measures its models the same way: its
loss is :math:`\\frac1N \\sum_t e^T W e` over the one-step prediction errors (over the
simulation errors with ``Focus="simulation"``, the same errors for a model whose noise model is
trivial), and its ``pe`` documentation estimates the variance of the noise source ``e(t)``
(an identified model's ``NoiseVariance``) from a model's prediction errors. :math:`1/N`, no
degrees-of-freedom
correction: the maximum-likelihood estimate given the model; the correction
:math:`N l / (N l - d)` for ``d`` parameters (:func:`sysid.information_criteria`) is 1.0015 at
the thesis size (``d`` = 136, ``N l`` = 90 000) and only matters on records too short for the
model.

A model with K = 0 (an output-error model: PEM with the simulation focus, PO-MOESP's thesis
variant) predicts one step by simulating, so its ``noise_cov`` is the covariance of its
simulation errors, the additive output noise such a model assumes. The estimate the method's
last step made (IEM and PO-MOESP: the covariance of the subspace step's innovation estimate
:math:`\\hat E_{f0}`, or of the Kalman fallback's state residuals; PARSIM-K: of its predictor
fit's errors; PEM: of its own errors) is kept in ``provenance["noise_cov_method"]``, and
``provenance["noise_cov_source"]`` says which one ``noise_cov`` is. The method's estimate stays
``noise_cov`` when ``A - K C`` is unstable (the model's own predictor diverges;
:func:`sysid.stable_predictor` gives a stable K with its covariance) or the errors overflow.

Cost: one run of the predictor and one initial-state fit per flight, ``O(N l n^2)``: at the
thesis size (N = 15 000, n = 8, l = 6) 14-21 ms, half to two thirds of identifying it. A
sweep scores hundreds of models and drops them: inside :func:`without_own_noise_cov` (the
sweep's models it does not keep) it is not computed, and ``provenance["noise_cov_source"]``
says so.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Iterator, Sequence

import numpy as np

from sysid.data import IOData
from sysid.kalman import error_covariance, one_step_errors
from sysid.model import StateSpaceModel

__all__ = ["OWN", "own_noise_cov", "without_own_noise_cov"]

#: Whether :func:`own_noise_cov` computes; off inside :func:`without_own_noise_cov`.
_COMPUTE: contextvars.ContextVar[bool] = contextvars.ContextVar("own_noise_cov", default=True)
#: ``provenance["noise_cov_source"]`` of a model whose ``noise_cov`` is its own.
OWN = "one-step prediction errors on the identification data"


@contextlib.contextmanager
def without_own_noise_cov() -> Iterator[None]:
    """Inside the block identified models keep the method's ``noise_cov`` (for models that are
    scored and dropped: :mod:`sysid.sweep` without ``keep_models``)."""
    token = _COMPUTE.set(False)
    try:
        yield
    finally:
        _COMPUTE.reset(token)


def own_noise_cov(model: StateSpaceModel, *, flights: Sequence[IOData]) -> StateSpaceModel:
    """``model`` with ``noise_cov`` ``(l, l)`` the covariance of its own one-step prediction
    errors on ``flights`` (``u (N_i, m)``, ``y (N_i, l)``, physical units; module docstring),
    the estimate it had in ``provenance["noise_cov_method"]`` (None if it had none)."""
    given = model.noise_cov
    prov = {**model.provenance, "noise_cov_method": None if given is None else given.tolist()}
    if not _COMPUTE.get():
        source = "the method's estimate (not computed: a sweep's dropped model)"
    elif not model.predictor_is_stable:
        source = "the method's estimate: the predictor A - K C is unstable"
    else:
        errs, _ = one_step_errors(model, flights=flights)
        with np.errstate(over="ignore", invalid="ignore"):
            cov = error_covariance(errs)
        if np.isfinite(cov).all():
            return model.replace(noise_cov=cov, provenance={**prov, "noise_cov_source": OWN})
        source = "the method's estimate: the one-step errors overflow"
    if given is None:  # "the method's estimate" would name one that is not there
        source = source.replace("the method's estimate", "none (the method gave none)", 1)
    return model.replace(provenance={**prov, "noise_cov_source": source})
