"""The emulated Crazyradio PA under unmodified cflib: USB descriptors and vendor requests as the
firmware has them, delivery by channel/rate/address, and the user errors a real dongle gives (no
dongle, old firmware, wrong channel, unplugged). Noise: ``test_radio_noise.py`` and
``test_radio_loss.py``; a vehicle that stops answering: ``test_radio_link_loss.py``."""

from __future__ import annotations

import errno
import logging
import time

import pytest
import usb.core
from cflib.drivers.crazyradio import Crazyradio

from cfsession.reader import open_session
from groundstation.errors import LinkError
from groundstation.flight import fly_plan
from groundstation.flight.link import install_drivers
from groundstation.sim.crazyradio_usb import emulated_radio, usb_backend

from .backend import SPEED, URI


def test_descriptors_are_a_crazyradio_pa(bus):
    dev = usb.core.find(idVendor=0x1915, idProduct=0x7777, backend=usb_backend())
    assert dev.bcdDevice == 0x0053 and dev.manufacturer == "Bitcraze"
    assert "Crazyradio PA" in dev.product and dev.serial_number
    eps = [e.bEndpointAddress for e in dev.get_active_configuration()[(0, 0)]] \
        if dev.set_configuration(1) is None else []
    assert eps == [0x81, 0x01]
    radio = Crazyradio()  # cflib's own driver
    assert radio.version == pytest.approx(0.53)
    assert bus.dongles[0].configured()["channel"] == 2  # cflib's init: channel 2, 2M, E7..
    radio.set_channel(80)
    radio.set_data_rate(Crazyradio.DR_250KPS)
    radio.set_address((1, 2, 3, 4, 5))
    radio.set_power(Crazyradio.P_M18DBM)
    conf = bus.dongles[0].configured()
    assert (conf["channel"], conf["data_rate"], conf["address"], conf["power"]) == (
        80, "250K", "0102030405", 0)
    with pytest.raises(usb.core.USBError) as err:  # a 4-byte address stalls, as the firmware
        radio.handle.ctrl_transfer(0x40, 0x02, 0, 0, (1, 2, 3, 4))
    assert err.value.errno == errno.EPIPE
    radio.handle.ctrl_transfer(0x40, 0x01, 126, 0, ())  # out of range: ignored
    assert bus.dongles[0].configured()["channel"] == 80
    radio.close()


def test_only_the_vehicle_on_its_channel_rate_and_address_answers(bus):
    radio = Crazyradio()
    radio.set_arc(3)
    for channel, rate, address, heard in [(80, 2, (0xE7,) * 5, True), (81, 2, (0xE7,) * 5, False),
                                          (80, 0, (0xE7,) * 5, False),
                                          (80, 2, (0xE7,) * 4 + (0xE8,), False)]:
        radio.set_channel(channel)
        radio.set_data_rate(rate)
        radio.set_address(address)
        ack = radio.send_packet((0xFF,))
        assert ack.ack is heard, (channel, rate, address)
    radio.set_channel(80)
    radio.set_data_rate(2)
    radio.set_address((0xE7,) * 5)
    radio.send_packet((0xFC, 0x68, 0x69))  # LINKCTRL echo: the reply comes in a later ack
    replies = [tuple(radio.send_packet((0xFF,)).data) for _ in range(20)]
    assert (0xFC, 0x68, 0x69) in replies
    radio.close()


def test_no_dongle_old_firmware_and_wrong_channel_are_one_line(tmp_path):
    install_drivers()
    with emulated_radio(dongles=0), pytest.raises(LinkError, match=r"no Crazyradio found.*udev"):
        fly_plan(plan="hover-check", out=tmp_path, uri=URI)
    with emulated_radio(firmware_bcd=0x0025), pytest.raises(LinkError,
                                                          match=r"firmware is 0\.25, older"):
        fly_plan(plan="hover-check", out=tmp_path, uri=URI)
    with emulated_radio(speed=SPEED), pytest.raises(LinkError, match="groundstation scan") as e:
        fly_plan(plan="hover-check", out=tmp_path, uri="radio://0/81/2M/E7E7E7E7E7")
    assert "\n" not in str(e.value)
    assert not list(tmp_path.iterdir())


@pytest.mark.filterwarnings("error::pytest.PytestUnhandledThreadExceptionWarning")
def test_unplugged_mid_flight_aborts_and_the_watchdog_stops_the_vehicle(bus, tmp_path, caplog):
    """... and cflib's threads that die with the link (its ping thread joins itself) are one
    log line each, not a traceback on stderr."""
    def unplug(k: int) -> None:
        if k == 40:
            bus.dongles[0].unplug()

    result = fly_plan(plan="hover-check", out=tmp_path, uri=URI, tick_hook=unplug)
    assert result.aborted and result.cause.startswith("link lost")
    v = bus.vehicles[0].sim.vehicle  # no setpoint for 2 s: the watchdog stops the motors
    deadline = time.monotonic() + 30.0
    while not (v.stop_count >= 1 and not any(v.motors_pwm)) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert v.stop_count >= 1 and not any(v.motors_pwm)
    s = open_session(result.path)
    assert s.closed_cleanly and any("watchdog" in e.text for e in s.events())
    assert 40 <= s["setpoints"].data["tick"].max() < 60
    for r in caplog.records:
        if r.name == "groundstation.flight.thread_errors" and r.levelno >= logging.WARNING:
            assert r.exc_info is None and "\n" not in r.getMessage()
