"""Singular values for model-order selection (thesis section 5.1.2, Figure 5.1)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from sysid.data import IOData
from sysid.errors import ParameterError
from sysid.factor import build_products
from sysid.iem import iem_signals
from sysid.moesp import moesp_factor

__all__ = ["singular_values"]

_METHODS = ("iem", "po-moesp")


def singular_values(data: IOData | Sequence[IOData], *, past: int, future: int,
                    method: str = "iem", feedthrough: bool | None = None,
                    weighting: str = "data", scale: bool = True) -> np.ndarray:
    """Singular values ``(min(f l, p (m+l)),)`` of the matrix whose SVD sets the order.

    IEM: :math:`\\widehat{\\Gamma_f L_p} Z_p / \\sqrt{M}` (``weighting="data"``) or
    :math:`\\widehat{\\Gamma_f L_p}` (``"none"``, eq. 3.32); PO-MOESP: ``[L42 L43] / sqrt(M)``
    (eq. 3.17). ``M`` is the number of Hankel columns, so values do not grow with N.
    ``feedthrough`` defaults to False for IEM and True for PO-MOESP, as in those functions.
    The same values are stored in ``model.provenance["singular_values"]``.
    """
    method = method.replace("_", "-")  # "po_moesp" as in the function's name
    if method not in _METHODS:
        raise ParameterError(f"method={method!r}; use one of {_METHODS}")
    products = build_products(data, past=past, future=future, scale=scale)
    if method == "po-moesp":
        l4, _, _ = moesp_factor(products)
        return np.linalg.svd(l4 / np.sqrt(products.n_columns), compute_uv=False)
    gamma_lp, sig = iem_signals(products, feedthrough=bool(feedthrough))
    o = gamma_lp @ sig.zp / np.sqrt(sig.n_columns) if weighting == "data" else gamma_lp
    return np.linalg.svd(o, compute_uv=False)
