"""Tests that fly a real Crazyflie: ``pytest hw_tests --uri radio://0/80/2M/E7E7E7E7E7`` (or set
``CF_URI``). Without a URI every test is skipped. See hw_tests/README.md."""

from __future__ import annotations

import os

import pytest


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption("--uri", default=None,
                     help="Crazyflie URI to fly (default: $CF_URI); tests skip without one")
    parser.addoption("--arm", action="store_true",
                     help="arm the Crazyflie before each flight (a Crazyflie Brushless: "
                          "groundstation fly --arm)")


@pytest.fixture
def cf_uri(request: pytest.FixtureRequest) -> str:
    uri = request.config.getoption("--uri") or os.environ.get("CF_URI")
    if not uri:
        pytest.skip("no Crazyflie: give --uri URI or set CF_URI")
    return uri


@pytest.fixture
def cf_arm(request: pytest.FixtureRequest) -> bool:
    """Whether each flight arms the vehicle first (``--arm``)."""
    return bool(request.config.getoption("--arm"))
