"""Exceptions that escape cflib's own threads, as one log line instead of a traceback.

cflib runs its link in threads of its own (the radio driver's, the packet handler, the link
statistics' ping thread). When a link dies some of them raise where nothing catches it: a
Crazyradio unplugged mid-flight fills the radio driver's queue, the ping thread's send reports
the link error, and cflib's disconnect handler, running in that thread, joins it
(``RuntimeError: cannot join current thread``); Python then prints the thread's traceback on
stderr beside the ground station's own one-line abort. The flight's outcome is the ground
station's (the link watch sees the link lost and aborts); the thread's end is a symptom of it.
:func:`log_cflib_thread_errors` puts a hook in front of :data:`threading.excepthook` that logs
such an exception as one warning (its traceback at debug level) and passes every other thread's
exception on unchanged, as it does one that passed through the ground station's own code (a
callback of ours that a cflib thread ran)."""

from __future__ import annotations

import logging
import sys
import threading
from pathlib import Path
from types import TracebackType

__all__ = ["log_cflib_thread_errors"]

log = logging.getLogger(__name__)


_OURS = ("groundstation", "cfsession", "cfcommon", "sysid")
"""This project's packages: an exception that passed through their code is never cflib's."""


def _in_cflib(tb: TracebackType | None) -> bool:
    """Whether the exception is cflib's own: the thread's code (its outermost frame below
    ``threading``) is cflib's and no frame on the way is this project's (a callback of ours
    that cflib's thread ran raised: that is our bug, and keeps its traceback)."""
    import cflib

    root = Path(cflib.__file__).resolve().parent
    ours = [Path(file).resolve().parent for name in _OURS
            if (file := getattr(sys.modules.get(name), "__file__", None))]
    started = None
    while tb is not None:
        path = Path(tb.tb_frame.f_code.co_filename).resolve()
        if any(path.is_relative_to(p) for p in ours):
            return False
        if started is None and path.name != "threading.py":
            started = path
        tb = tb.tb_next
    return started is not None and started.is_relative_to(root)


def log_cflib_thread_errors() -> None:
    """Put the hook in front of the current :data:`threading.excepthook` (idempotent; a hook
    put in front of it later gets it in front again on the next connect)."""
    previous = threading.excepthook
    if getattr(previous, "_cflib_thread_errors", False):
        return

    def hook(args: threading.ExceptHookArgs) -> None:
        if args.exc_type is SystemExit or not _in_cflib(args.exc_traceback):
            previous(args)
            return
        name = args.thread.name if args.thread is not None else "?"
        text = str(args.exc_value).strip().splitlines()
        log.warning("cflib's %s thread ended: %s%s", name, args.exc_type.__name__,
                    f": {text[0]}" if text else "")
        log.debug("cflib's %s thread", name,
                  exc_info=(args.exc_type, args.exc_value, args.exc_traceback))

    hook._cflib_thread_errors = True  # type: ignore[attr-defined]
    threading.excepthook = hook
