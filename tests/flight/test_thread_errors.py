"""An exception that ends one of cflib's threads is one log line (its traceback at debug level);
every other thread's exception still reaches the hook that was there before."""

from __future__ import annotations

import logging
import threading

import pytest
from cflib.crtp.crtpstack import CRTPPacket
from cflib.utils.callbacks import Caller

from groundstation.errors import PlanError
from groundstation.flight.thread_errors import log_cflib_thread_errors
from groundstation.plan import parse_plan


@pytest.fixture(autouse=True)
def _own_hook(monkeypatch):
    """The hook this test puts in is gone after it."""
    monkeypatch.setattr(threading, "excepthook", threading.excepthook)


def _run(target, *args) -> None:
    t = threading.Thread(target=target, args=args, name="worker")
    t.start()
    t.join()


@pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")
def test_a_cflib_thread_that_raises_is_one_warning_line(caplog):
    log_cflib_thread_errors()
    log_cflib_thread_errors()  # idempotent: one hook, one line
    with caplog.at_level(logging.DEBUG, logger="groundstation.flight.thread_errors"):
        _run(CRTPPacket, "not a header")  # cflib's own code raises in the thread
    warnings = [r for r in caplog.records if r.levelno == logging.WARNING]
    assert len(warnings) == 1
    text = warnings[0].getMessage()
    assert text.startswith("cflib's worker thread ended: TypeError") and "\n" not in text
    assert any(r.levelno == logging.DEBUG and r.exc_info for r in caplog.records)


def test_other_threads_exceptions_reach_the_previous_hook(monkeypatch):
    seen = []
    monkeypatch.setattr(threading, "excepthook", lambda args: seen.append(args.exc_type))
    log_cflib_thread_errors()

    def ours() -> None:
        raise ValueError("not cflib's")

    _run(ours)
    assert seen == [ValueError]


def test_our_code_raising_in_a_cflib_thread_keeps_its_traceback(monkeypatch):
    """A callback of the ground station that cflib's thread runs is our bug, not cflib's."""
    seen = []
    monkeypatch.setattr(threading, "excepthook", lambda args: seen.append(args.exc_type))
    log_cflib_thread_errors()
    caller = Caller()
    caller.add_callback(lambda: parse_plan(text="not a plan", source="x.toml"))
    _run(caller.call)
    assert seen == [PlanError]


@pytest.mark.parametrize(("message", "reason"), [("", "no reason given"),
                                                 ("Too many packets lost!\nmore", "Too many "
                                                  "packets lost!")])
def test_a_link_lost_without_a_reason_is_still_posted(message, reason):
    """cflib's connection_lost with an empty message: the loss is posted, not an IndexError in
    cflib's thread (which the hook above would have passed on as ours)."""
    from types import SimpleNamespace

    from groundstation.flight.clock import MonotonicClock
    from groundstation.flight.link import Link

    posted = []
    link = SimpleNamespace(lost=False, clock=MonotonicClock(), _post=posted.append)
    Link._on_lost(link, "radio://0/80/2M", message)
    assert link.lost and [p[0] for p in posted] == ["lost"] and posted[0][2] == reason
