"""Closed-loop subspace identification: IEM and PO-MOESP.

>>> import sysid
>>> data = sysid.IOData(u=u, y=y, dt=0.02)                       # doctest: +SKIP
>>> model = sysid.iem(data, order=8, past=60, future=17)          # doctest: +SKIP
"""

from sysid.data import IOData
from sysid.errors import (
    DataError,
    DimensionError,
    HorizonError,
    MissingDependencyError,
    ModelFileError,
    OrderError,
    SysIdError,
)
from sysid.model import StateSpaceModel, load_model

__all__ = [
    "DataError",
    "DimensionError",
    "HorizonError",
    "IOData",
    "MissingDependencyError",
    "ModelFileError",
    "OrderError",
    "StateSpaceModel",
    "SysIdError",
    "load_model",
]
