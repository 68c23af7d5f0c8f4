"""Helpers both command lines use, owned by neither side.

:mod:`cfcommon.cli` (finite floats, the output-file rule, the one-line user-error group) and
:mod:`cfcommon.rerun` (opening a Rerun recording: save, serve, spawn). Imports neither
``groundstation`` nor ``sysid``.
"""
