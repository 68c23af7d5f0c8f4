"""The emulated-radio checks of ``tests/sim_radio`` on a real Crazyradio and Crazyflie:
``pytest hw_tests --uri radio://0/80/2M/E7E7E7E7E7``. Skipped without a URI or for a URI that
is not ``radio://``. What only hardware shows (range, interference, the PA's power levels) is
in docs/flying.md; these check that the emulation's claims hold on the real dongle.
"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main


@pytest.fixture
def radio_uri(cf_uri: str) -> str:
    if not cf_uri.startswith("radio://"):
        pytest.skip("a radio:// URI is needed for the Crazyradio checks")
    return cf_uri


def _parts(uri: str) -> tuple[int, str, str]:
    """``(channel, data rate, address)`` of a radio URI, as cflib's own radio driver reads it."""
    from cflib.crtp.radiodriver import RadioDriver

    _, channel, rate, address, _ = RadioDriver.parse_uri(uri)
    return channel, ("250K", "1M", "2M")[rate], bytes(address).hex().upper()


def test_scan_lists_the_dongle_and_the_vehicle(radio_uri):
    res = CliRunner().invoke(main, ["scan"])
    assert res.exit_code == 0, res.output
    assert any(ln.startswith("usb 1915:7777 Crazyradio") for ln in res.output.splitlines())
    channel, rate, _ = _parts(radio_uri)
    assert f"crazyflie radio://0/{channel}/{rate}" in res.output


def test_fly_records_the_configuration_of_the_dongle_and_the_link(radio_uri, cf_arm, tmp_path):
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", radio_uri,
                                    "--out", str(tmp_path), "--json",
                                    *(["--arm"] if cf_arm else [])])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    s = open_session(summary["file"])
    channel, rate, address = _parts(radio_uri)
    radio = s.json_meta("radio")
    assert (radio["channel"], radio["data_rate"], radio["address"]) == (channel, rate, address)
    # a vehicle a metre away: nearly every packet acknowledged at the first try
    quality = s["link"].data["quality"]
    assert len(quality) > 0 and float(quality[quality == quality].mean()) > 90
