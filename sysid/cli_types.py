"""The former path of the command-line pieces both CLIs share, kept for callers:
``from sysid.cli_types import FiniteFloat, check_output``.

They now live in :mod:`cfcommon.cli`, owned by neither side; this module only re-exports the names
``sysid/cli_types.py`` used to define, the same objects.
"""

from cfcommon.cli import FiniteFloat, check_output

__all__ = ["FiniteFloat", "check_output"]
