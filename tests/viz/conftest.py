"""Rerun in strict mode for the viz tests: a malformed log call raises instead of warning."""

from __future__ import annotations

import pytest
import rerun as rr


@pytest.fixture(autouse=True)
def _strict_rerun():
    before = rr.strict_mode()
    rr.set_strict_mode(True)
    yield
    rr.set_strict_mode(before)
