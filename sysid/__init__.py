"""Closed-loop subspace identification: IEM, PARSIM-K and PO-MOESP.

>>> import sysid
>>> data = sysid.IOData(u=u, y=y, dt=0.02)                       # doctest: +SKIP
>>> model = sysid.iem(data, order=8, past=60, future=17)          # doctest: +SKIP
>>> model = sysid.identify(data).model   # horizons, order, focus, method chosen  # doctest: +SKIP
"""

from sysid.comparison import CompareResult
from sysid.data import IOData
from sysid.errors import (
    DataError,
    DimensionError,
    HorizonError,
    MissingDependencyError,
    ModelFileError,
    OrderError,
    ParameterError,
    SysIdError,
)
from sysid.iem import iem
from sysid.kalman import stable_predictor
from sysid.model import StateSpaceModel, load_model
from sysid.moesp import po_moesp
from sysid.no_knobs import identify
from sysid.order import InformationCriteria, information_criteria, singular_values
from sysid.parsim import parsim_k
from sysid.preprocess import Stream, detrend_data, iodata_from_streams, trim, zoh_resample
from sysid.residuals import ResidualResult, residuals
from sysid.sweep import SweepResult, select_order, sweep
from sysid.validate import compare, fit_percent

__all__ = [
    "CompareResult",
    "DataError",
    "DimensionError",
    "HorizonError",
    "IOData",
    "InformationCriteria",
    "MissingDependencyError",
    "ModelFileError",
    "OrderError",
    "ParameterError",
    "ResidualResult",
    "StateSpaceModel",
    "Stream",
    "SweepResult",
    "SysIdError",
    "compare",
    "detrend_data",
    "fit_percent",
    "identify",
    "iem",
    "information_criteria",
    "iodata_from_streams",
    "load_model",
    "parsim_k",
    "po_moesp",
    "residuals",
    "select_order",
    "singular_values",
    "stable_predictor",
    "sweep",
    "trim",
    "zoh_resample",
]
