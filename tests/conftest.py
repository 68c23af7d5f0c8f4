"""Suite-wide pytest hooks.

Under ``pytest -n 2 --dist loadfile`` (``make test``) every test that runs the real firmware in
the loop (a ``sitl`` parameter, or anything under ``tests/sitl/``) goes to one xdist scope, so at
most one real-time firmware runs at a time and the other worker keeps the rest of the suite;
that scope is sent first, being the longest, then the longest other files. Connects cache the
firmware's TOCs in a folder of the run (:func:`pytest_configure`). Each xdist worker gives
BLAS its share of the cores (:func:`_blas_threads`); a worker lowers its own priority once it
runs a test outside the firmware's scope (:func:`pytest_runtest_setup`).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile

_BLAS_THREADS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def _blas_threads() -> None:
    """In an xdist worker, at most cores / workers BLAS threads (unless the environment says
    otherwise), set before numpy loads here and inherited by the commands the tests start.
    OpenBLAS, as numpy and scipy ship it, otherwise starts one thread per core in every
    worker, and its idle threads spin: two workers on two cores ran four, and tests/sysid
    took 94 s of wall time (179 s of CPU) instead of 38 s (67 s)."""
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT") or 0)
    if workers < 1:
        return
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    for name in _BLAS_THREADS:
        os.environ.setdefault(name, str(max(1, (cores or 1) // workers)))


_blas_threads()  # before anything imports numpy (groundstation does: imported lazily below)


def pytest_configure(config):
    """cflib's TOC cache in a folder of this run, not the user's ``~/.cache`` (each xdist worker
    and the commands it starts share one)."""
    from groundstation.flight.drivers import TOC_CACHE_ENV

    os.environ[TOC_CACHE_ENV] = tempfile.mkdtemp(prefix="groundstation-toc-")


def pytest_unconfigure(config):
    from groundstation.flight.drivers import TOC_CACHE_ENV

    shutil.rmtree(os.environ.pop(TOC_CACHE_ENV, ""), ignore_errors=True)


_LONG_FILES = ("tests/flight/test_liveid.py", "tests/flight/test_aliased_flights.py",
               "tests/test_docs_examples.py", "tests/sim_crtp/test_udp.py",
               "tests/flight/test_connect.py", "tests/demo/test_demo.py", "tests/fuzz/test_fuzz.py",
               "tests/sim_crtp/test_link.py", "tests/sysid/test_cli.py",
               "tests/sysid/test_cli_robustness.py", "tests/flight/test_repeatable.py")
"""The longest files outside the firmware's scope (5-30 s each on 2 cores, measured with
``--durations``; the other flight files of 5-22 s come first by themselves), longest first;
the collection order put several of them near the end."""


def _is_sitl(nodeid: str) -> bool:
    path, _, params = nodeid.partition("[")
    return path.startswith("tests/sitl/") or "sitl" in params.rstrip("]").split("-")


_NICE = 10
"""Niceness a worker takes for the tests outside the firmware's scope (and the commands they
start): the real-time firmware and the ground station flying it get the CPU first when both
workers want it."""
_niced = False


def pytest_runtest_setup(item):
    """In an xdist worker, lower this process's priority (:data:`_NICE`, once: it cannot be
    raised again unprivileged) at its first test outside the firmware's scope. The firmware
    runs in real time, so a flight whose host starves it for 0.5 s reads as link loss (a
    signal test aborted on "no log packet for 0.68 s" beside two CPU-bound processes); the
    other tests count simulated time or wait for conditions, and only run slower. The
    firmware's scope runs first in its worker (:func:`pytest_xdist_make_scheduler`), so only
    the other worker is lowered while it runs."""
    global _niced
    if os.environ.get("PYTEST_XDIST_WORKER") and not _is_sitl(item.nodeid) and not _niced:
        _niced = True
        with contextlib.suppress(OSError):  # not allowed: the tests run at the usual priority
            os.nice(_NICE)


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
