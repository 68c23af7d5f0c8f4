"""Crazyflie flight-test ground station: fly plans, record HDF5 sessions, view them in Rerun."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("cf-sysid")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
