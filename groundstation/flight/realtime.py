"""Process-level settings for the time a flight runs: signal handlers and prompt thread switches.

Both are installed by :func:`groundstation.flight.fly_plan` for the flight only and restored after.
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Callable, Iterator

__all__ = ["prompt_thread_switches", "signal_handlers"]


@contextlib.contextmanager
def prompt_thread_switches(interval_s: float = 0.0005) -> Iterator[None]:
    """While flying, hand the GIL over every 0.5 ms instead of CPython's 5 ms, so the runner's
    thread wakes on its deadline even while cflib's threads run Python code (restored after)."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(min(previous, interval_s))
    try:
        yield
    finally:
        sys.setswitchinterval(previous)


_HANGUP = (signal.SIGHUP,) if hasattr(signal, "SIGHUP") else ()  # POSIX only
#: Ctrl-\\ (SIGQUIT) killed the process mid-flight with no stop setpoint; Ctrl-Z (SIGTSTP)
#: suspended it, and the Crazyflie's watchdog cut the motors 2 s later.
_KEYS = tuple(getattr(signal, name) for name in ("SIGQUIT", "SIGTSTP") if hasattr(signal, name))
_ONCE = (*_HANGUP, *(s for s in _KEYS if s.name == "SIGTSTP"))  # count once (docstring)


@contextlib.contextmanager
def signal_handlers(abort: Callable[[str], None]) -> Iterator[None]:
    """SIGINT, SIGTERM, SIGHUP (the terminal closed, an SSH session dropped), SIGQUIT (Ctrl-\\)
    and SIGTSTP (Ctrl-Z: the process is not suspended) request an abort while flying (main
    thread only); restored after. SIGHUP's and SIGQUIT's defaults killed the process mid-flight
    with no stop setpoint and the session left open; SIGTSTP's stopped the setpoints.

    A second SIGINT, SIGTERM or SIGQUIT is the operator's second request (the descent ends, the
    stop is sent at once); SIGHUP and SIGTSTP count once: one hangup can arrive twice (the
    kernel's to the terminal's process group, then the shell's to its jobs), a job-control
    stop likewise, and it is no one's decision to skip the descent. SIGHUP ignored when the
    flight starts (``nohup``) stays ignored."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    once: set[int] = set()

    def request(n: int, _frame: object) -> None:
        if n in _ONCE:
            if n in once:
                return
            once.add(n)
        abort(f"{signal.Signals(n).name} received")

    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM, *_HANGUP, *_KEYS):
        if sig in _HANGUP and signal.getsignal(sig) is signal.SIG_IGN:
            continue  # nohup: the operator asked for the flight to outlive the terminal
        previous[sig] = signal.signal(sig, request)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
