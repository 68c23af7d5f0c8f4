"""Where the tests find the repository and the team's shared data, relative to this checkout.

The shared reference data (``shared/`` beside the repository: real flight logs, DaISy sets) is
looked up next to the repository root, or where ``CF_SYSID_SHARED`` points.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
SHARED = Path(os.environ.get("CF_SYSID_SHARED", REPO.parent / "shared"))
CRAZYPAD = SHARED / "data" / "crazypad"
"""Real Crazyflie 2.1 uSD logs (CrazyPAD); tests that need them skip when they are absent."""

needs_crazypad = pytest.mark.skipif(not CRAZYPAD.is_dir(),
                                    reason=f"shared CrazyPAD logs not found at {CRAZYPAD}")
