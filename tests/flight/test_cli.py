"""``groundstation fly`` and ``groundstation scan`` from the command line."""

from __future__ import annotations

import json
import os
import sys

import pytest
import usb.core
from click.testing import CliRunner

from cfsession import open_session
from groundstation.cli import main
from groundstation.commands.fly import PlainProgress, summary_lines


def test_fly_prints_the_summary_and_records(sim_uri, tmp_path):
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", sim_uri(), "--out",
                                    str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)  # progress lines go to stderr
    assert summary["setpoints"]["scheduled"] == 100 and not summary["aborted"]
    s = open_session(summary["file"])
    assert s.closed_cleanly and summary["file"].startswith(str(tmp_path))
    assert s.json_meta("summary")["setpoints"] == summary["setpoints"]
    # every recorded setpoint row is counted: the plan's and the unlock on the grid, the stop
    # apart (the summary said "+1 unlock/abort" for two extra rows: first-day audit), then
    # the stop fed until the Crazyflie reported landed
    sp = summary["setpoints"]
    fed = sp["after_stop"]
    assert sp["stopped"] and len(s["setpoints"]) == sp["sent"] + 1 + fed["setpoints"]
    assert f"then the stop, fed {fed['seconds']:g} s until landed)" in summary_lines(summary)[-2]


def test_fly_abort_exits_nonzero_with_cause_and_path(sim_uri, tmp_path):
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", sim_uri(cut_at=5.0),
                                    "--out", str(tmp_path)])
    assert res.exit_code == 2
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("error: flight aborted: link lost") and str(tmp_path) in last
    assert "gyro" in res.output and "dropped" in res.output  # the summary came first
    # the summary on stdout, the record kept, says so (it read as a success: first-day review)
    assert res.stdout.splitlines()[1].startswith("  ABORTED: link lost")
    path = last.rsplit(" ", 1)[-1]
    assert open_session(path).closed_cleanly
    info = CliRunner().invoke(main, ["info", path]).output.splitlines()
    assert info[0].endswith("closed cleanly, flight ABORTED (its cause is under the flight "
                            "summary)")
    assert any(line.strip().startswith("ABORTED: link lost") for line in info)


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX pipes")
def test_an_aborted_flight_whose_summary_pipe_closed_still_says_so_on_stderr(tmp_path):
    """``groundstation fly ... | head -1`` on a terminal: the summary's pipe closed, and the
    error line that says how the flight ended and where its session is went to the null
    device with it (standard error pointed there too, though it still worked). The exit
    status said 2; the line is on standard error now. The pipe's reader is closed before the
    command starts, so its first write fails, whatever the timing."""
    import subprocess

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    code = "import sys; from groundstation.cli import main; sys.argv[0] = 'groundstation'; main()"
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-c", code, "fly", "hover-check", "--uri",
                               "sim://0?speed=inf&autoarm=0", "--out", str(tmp_path)],
                              stdout=write, stderr=subprocess.PIPE, text=True, timeout=120,
                              cwd=root)
    finally:
        os.close(write)
    (path,) = tmp_path.glob("*.h5")
    assert done.returncode == 2, done.stderr
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("error: flight aborted: the Crazyflie is not armed"), done.stderr
    assert last.endswith(f"; session saved to {path}")


@pytest.mark.parametrize("code", [0, 3])
def test_a_listener_exiting_mid_flight_is_an_aborted_flight_with_its_summary(
        code, sim_uri, tmp_path, monkeypatch):
    """A listener's ``SystemExit(0)`` aborted the flight (it landed and was recorded as
    aborted), then went through ``fly`` unseen: no summary and exit 0, an aborted flight read
    as a success. Now the summary with its ABORTED line, then the one line and exit 2 of any
    abort, whatever the code (3 too: 2 is what tells a script the flight was aborted)."""
    real = PlainProgress.rows

    def quitting(self, stream, rows):
        if stream == "setpoints" and any(r[6] == 20 for r in rows):
            raise SystemExit(code)
        return real(self, stream, rows)

    monkeypatch.setattr(PlainProgress, "rows", quitting)
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", sim_uri(), "--out",
                                    str(tmp_path)])
    assert res.exit_code == 2, res.output
    cause = f"PlainProgress.rows failed (SystemExit: {code}): the flight ends"
    (path,) = tmp_path.glob("*.h5")
    assert res.stdout.splitlines()[1] == f"  ABORTED: {cause}"
    assert res.stdout.splitlines()[-1] == f"  file {path}"
    assert res.output.strip().splitlines()[-1] == (f"error: flight aborted: {cause}; "
                                                   f"session saved to {path}")
    assert "Traceback" not in res.output
    s = open_session(path)
    assert s.closed_cleanly and s.json_meta("summary")["cause"] == cause


@pytest.mark.parametrize(("code", "status"), [(0, 0), (None, 0), (3, 2)])
def test_a_listener_exiting_after_the_landing_keeps_a_whole_flight(
        code, status, sim_uri, tmp_path, monkeypatch):
    """After the landing the flight is whole: the summary has no ABORTED line; a listener's
    exit code 0 is exit 0, any other one line and exit 2."""
    def quitting(self, **_kw):
        raise SystemExit(code)

    monkeypatch.setattr(PlainProgress, "end", quitting)
    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", sim_uri(), "--out",
                                    str(tmp_path)])
    assert res.exit_code == status, res.output
    (path,) = tmp_path.glob("*.h5")
    assert "ABORTED" not in res.stdout and res.stdout.splitlines()[-1] == f"  file {path}"
    errors = [ln for ln in res.output.splitlines() if ln.startswith("error")]
    assert errors == ([] if status == 0 else [
        f"error: a listener exited (SystemExit: {code}) after the landing; session saved to "
        f"{path}"])


def test_fly_bad_plan_is_one_line(tmp_path):
    res = CliRunner().invoke(main, ["fly", "no-such-plan", "--out", str(tmp_path)])
    assert res.exit_code == 2 and res.output.count("\n") == 1 and "no such plan" in res.output


def test_view_without_live_module_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "groundstation.live", None)  # import fails
    res = CliRunner().invoke(main, ["fly", "hover-check", "--view", "rerun", "--out",
                                    str(tmp_path)])
    assert res.exit_code == 2 and "use --view none" in res.output
    assert res.output.count("\n") == 1 and not list(tmp_path.iterdir())


def test_scan_without_dongle_names_the_fix(monkeypatch):
    monkeypatch.setattr(usb.core, "find", lambda **kw: iter(()))
    monkeypatch.setattr("groundstation.commands.scan.scan_crazyflies", lambda addr: [])
    res = CliRunner().invoke(main, ["scan"])
    assert res.exit_code == 2
    assert res.output.startswith("error: no Crazyradio found") and "udev" in res.output
    assert "no simulator answered either" in res.output
    assert res.output.count("\n") == 1


def test_scan_lists_the_udp_simulator_and_warns_only_of_the_missing_dongle(monkeypatch):
    """``groundstation sim`` on port 19850 answers cflib's UDP scan; the warning said "a
    simulator is not scanned" under the simulator it had just listed."""
    import cflib.crtp.udpdriver as udpdriver

    from groundstation.sim import UdpServer
    from tests.sim_crtp.helpers import free_udp_port

    monkeypatch.setattr(usb.core, "find", lambda **kw: iter(()))
    port = free_udp_port()  # cflib scans 19850-19859: here one free port instead
    monkeypatch.setattr(udpdriver, "_BASE_PORT", port)
    monkeypatch.setattr(udpdriver, "_NR_OF_PORTS_TO_SCAN", 1)
    with UdpServer(port=port, seed=1):
        res = CliRunner().invoke(main, ["scan"])
    assert res.exit_code == 0, res.output
    assert f"crazyflie udp://127.0.0.1:{port}" in res.stdout
    assert res.stderr.startswith("warning: no Crazyradio found") and "simulator" not in res.stderr


def test_scan_without_usb_permission_or_backend(monkeypatch):
    class Dev:
        iSerialNumber, bus, address = 3, 1, 4

    def denied(dev, index):
        raise usb.core.USBError("Access denied", errno=13)

    monkeypatch.setattr(usb.core, "find", lambda **kw: iter([Dev()]))
    monkeypatch.setattr(usb.util, "get_string", denied)
    monkeypatch.setattr("groundstation.commands.scan.scan_crazyflies", lambda addr: [])
    res = CliRunner().invoke(main, ["scan"])
    assert res.exit_code == 2 and "no permission" in res.output and "plugdev" in res.output

    def no_backend(**kw):
        raise usb.core.NoBackendError("No backend available")

    monkeypatch.setattr(usb.core, "find", no_backend)
    res = CliRunner().invoke(main, ["scan"])
    assert res.exit_code == 2 and "libusb" in res.output


def test_scan_lists_simulated_crazyflies(sim_uri, monkeypatch):
    import groundstation.sim as gsim

    monkeypatch.setattr(usb.core, "find", lambda **kw: iter(()))
    uri = sim_uri()
    gsim.simulator_for_uri(uri)  # a powered-on simulated vehicle
    res = CliRunner().invoke(main, ["scan"])
    assert res.exit_code == 0, res.output
    address = uri.split("://")[1].split("?")[0]
    assert f"crazyflie sim://{address}" in res.output
    assert "warning: no Crazyradio" in res.output


def test_fly_without_a_radio_is_one_line_with_the_fix(tmp_path):
    """No Crazyradio on this machine: one line naming the fix, exit 2, no cflib traceback,
    no session file (run as a real process: cflib logs through the root logger)."""
    import subprocess

    res = subprocess.run(
        [sys.executable, "-c", "from groundstation.cli import main; main()", "fly",
         "hover-check", "--uri", "radio://0/80/2M/E7E7E7E7E7", "--out", str(tmp_path),
         "--timeout", "3"],
        capture_output=True, text=True, timeout=60,
    )
    assert res.returncode == 2, res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in res.stderr, res.stderr
    assert lines[0].startswith("error: cannot connect to radio://0/80/2M/E7E7E7E7E7")
    assert "Crazyradio" in lines[0] or "USB" in lines[0] or "libusb" in lines[0]
    assert not list(tmp_path.glob("*.h5"))


def test_info_shows_the_summary_stored_at_the_end_of_the_flight(sim_uri, tmp_path):
    """docs/flying.md points to `groundstation info FILE` for the stored summary; it showed
    neither in its table nor in --json (first-day audit)."""
    from groundstation.commands import info

    res = CliRunner().invoke(main, ["fly", "hover-check", "--uri", sim_uri(), "--out",
                                    str(tmp_path), "--json"])
    path = json.loads(res.stdout)["file"]
    shown = CliRunner().invoke(main, ["info", path, "--width", "200"])
    assert shown.exit_code == 0, shown.output
    assert "flight summary, stored when the flight ended" in shown.output
    assert "100 of 100 planned sent (+1 unlock/descent, then the stop, fed " in shown.output
    described = json.loads(CliRunner().invoke(main, ["info", path, "--json"]).stdout)
    assert described["summary"]["setpoints"]["stopped"] is True
    huge = {"blocks": {"acc": {"received": 10**400, "expected": 1, "dropped": 0}}}
    assert info._summary_text(huge) == ["  (the stored summary is malformed)"]
    # a flight file whose summary was damaged says so (it was left out without a word: review)
    import shutil

    import h5py

    for damaged in ({"setpoints": 3}, {"blocks": [1, 2]}):
        copy = tmp_path / f"damaged-{len(str(damaged))}.h5"
        shutil.copy(path, copy)
        with h5py.File(copy, "r+") as f:
            f.attrs["summary"] = json.dumps(damaged)
        shown = CliRunner().invoke(main, ["info", str(copy), "--width", "200"])
        assert shown.exit_code == 0, shown.output
        assert "(the stored summary is malformed)" in shown.output, shown.output
