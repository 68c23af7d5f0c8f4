"""Suite-wide pytest hooks.

Under ``pytest -n 2 --dist loadfile`` (``make test``) every test that runs the real firmware in
the loop (a ``sitl`` parameter, or anything under ``tests/sitl/``) goes to one xdist scope, so at
most one real-time firmware runs at a time and the other worker keeps the rest of the suite;
that scope is sent first, being the longest, then the longest other files. Connects cache the
firmware's TOCs in a folder of the run (:func:`pytest_configure`).
"""

from __future__ import annotations

import os
import shutil
import tempfile

from groundstation.flight.drivers import TOC_CACHE_ENV


def pytest_configure(config):
    """cflib's TOC cache in a folder of this run, not the user's ``~/.cache`` (each xdist worker
    and the commands it starts share one)."""
    os.environ[TOC_CACHE_ENV] = tempfile.mkdtemp(prefix="groundstation-toc-")


def pytest_unconfigure(config):
    shutil.rmtree(os.environ.pop(TOC_CACHE_ENV, ""), ignore_errors=True)


_LONG_FILES = ("tests/flight/test_liveid.py", "tests/flight/test_aliased_flights.py",
               "tests/test_docs_examples.py", "tests/flight/test_connect.py",
               "tests/sysid/test_batch.py", "tests/demo/test_demo.py", "tests/sysid/test_cli.py")
"""The longest files outside the firmware's scope (12-30 s each on 2 cores, measured with
``--durations``), longest first; the alphabetical order put three of them near the end."""


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

        def _assign_work_unit(self, node) -> None:
            # The firmware's scope is the longest (real time, about 4 min): first, so the
            # other worker's files fill the time beside it instead of trailing after it. The
            # longest other files next (largest first), so both workers end on short ones.
            if not getattr(self, "_ordered", False):
                for scope in (*reversed(_LONG_FILES), "sitl"):
                    if scope in self.workqueue:
                        self.workqueue.move_to_end(scope, last=False)
                self._ordered = True
            super()._assign_work_unit(node)

    return _SitlTogether(config, log)
