"""``--emulated-radio`` on ``groundstation scan`` and ``groundstation fly``, through the command
line: scan finds the emulated dongle and only the vehicle it can hear; fly records a session whose
radio metadata is what the emulated dongle was configured with (read back from the emulation)."""

from __future__ import annotations

import contextlib
import json

import pytest
from click.testing import CliRunner

import groundstation.sim.crazyradio_usb as crazyradio_usb
from cfsession import open_session
from groundstation.cli import main
from groundstation.dongle import firmware_version
from groundstation.sim.crazyradio_usb import installed_bus

from .backend import URI


@pytest.fixture
def buses(monkeypatch):
    """The emulated buses the commands install, kept for the test to read back."""
    made = []
    real = crazyradio_usb.emulated_radio

    @contextlib.contextmanager
    def keep(**kw):
        with real(**kw) as bus:
            made.append(bus)
            yield bus

    monkeypatch.setattr(crazyradio_usb, "emulated_radio", keep)
    return made


def test_scan_lists_the_emulated_dongle_and_its_vehicle(buses):
    res = CliRunner().invoke(main, ["scan", "--emulated-radio"])
    assert res.exit_code == 0, res.output
    lines = res.output.splitlines()
    dongle = buses[0].dongles[0]
    assert (f"usb 1915:7777 Crazyradio PA / 2.0 firmware 0.53 (bus 1 address "
            f"{dongle.bus_address}) serial {dongle.serial}") in lines
    # cflib scans every channel at 250K, 1M and 2M: only channel 80 at 2M answers (the default
    # address is left out of the URI)
    assert [ln for ln in lines if ln.startswith("crazyflie radio://")] == [
        "crazyflie radio://0/80/2M"]
    assert "warning" not in res.output and installed_bus() is None


def test_scan_at_another_address_hears_nothing(buses):
    res = CliRunner().invoke(main, ["scan", "--emulated-radio", "--address", "E7E7E7E7E8"])
    assert res.exit_code == 0, res.output
    assert "crazyflie radio://" not in res.output
    assert "no Crazyflie answered" in res.output


def test_fly_records_the_configuration_read_back_from_the_dongle(buses, tmp_path):
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", URI, "--emulated-radio",
                                    "--emulated-radio-speed", "20", "--out", str(tmp_path),
                                    "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert not summary["aborted"] and summary["setpoints"]["scheduled"] == 100
    dongle = buses[0].dongles[0]
    assert dongle.stats.acked > 1000  # the flight went through the emulated radio
    s = open_session(summary["file"])
    assert s.closed_cleanly and s.meta["uri"] == URI
    assert s.json_meta("radio") == {
        "dongle": 0, "channel": dongle.channel, "data_rate": dongle.data_rate_name,
        "address": dongle.address.hex().upper(),
        "dongle_firmware": firmware_version(dongle.firmware_bcd)}
    assert (dongle.channel, dongle.data_rate_name, dongle.address.hex().upper()) == (
        80, "2M", "E7E7E7E7E7")
    assert installed_bus() is None


def test_scan_lists_each_vehicle_once_when_cflib_drivers_were_initialised_twice(buses):
    import cflib.crtp

    before = list(cflib.crtp.CLASSES)
    try:
        cflib.crtp.init_drivers()  # cflib appends its drivers again: a second RadioDriver
        cflib.crtp.init_drivers()
        res = CliRunner().invoke(main, ["scan", "--emulated-radio"])
    finally:
        cflib.crtp.CLASSES[:] = before
    assert res.exit_code == 0, res.output
    assert [ln for ln in res.output.splitlines() if ln.startswith("crazyflie radio://")] == [
        "crazyflie radio://0/80/2M"]
