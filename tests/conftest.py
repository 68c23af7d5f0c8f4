"""Suite-wide pytest hooks.

Under ``pytest -n 2 --dist loadfile`` (``make test``) every test that runs the real firmware in
the loop (a ``sitl`` parameter, or anything under ``tests/sitl/``) goes to one xdist scope, so at
most one real-time firmware runs at a time and the other worker keeps the rest of the suite.
"""

from __future__ import annotations


def _is_sitl(nodeid: str) -> bool:
    path, _, params = nodeid.partition("[")
    return path.startswith("tests/sitl/") or "sitl" in params.rstrip("]").split("-")


def pytest_xdist_make_scheduler(config, log):
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    class _SitlTogether(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return "sitl" if _is_sitl(nodeid) else super()._split_scope(nodeid)

    return _SitlTogether(config, log)
