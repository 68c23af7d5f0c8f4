"""cfcommon.rerun: the one way both sides open a Rerun recording and keep a served viewer up."""

from __future__ import annotations

import os
import re

import psutil
import pytest
import rerun as rr

import cfcommon.rerun as rerun_io
from tests.viz.rrd import load


def test_save_mode_writes_a_readable_rrd_and_creates_its_folder(tmp_path):
    path = tmp_path / "new" / "x.rrd"
    rec, url = rerun_io.open_recording(name="x", mode="save", rrd_path=path)
    assert url is None
    rec.log("a/b", rr.TextDocument("hello"), static=True)
    rerun_io.close_file(rec, path)
    assert load(path)["/a/b"].static["TextDocument:text"][0] == "hello"


@pytest.mark.parametrize(("kwargs", "match"), [
    ({"mode": "web"}, "view mode 'web' is unknown"),
    ({"mode": "save"}, "needs rrd_path"),
])
def test_bad_modes_are_one_line_value_errors(kwargs, match):
    with pytest.raises(rerun_io.ViewModeError, match=match) as info:
        rerun_io.open_recording(name="x", **kwargs)
    assert isinstance(info.value, ValueError) and "\n" not in str(info.value)


def test_serve_until_interrupted_returns_on_ctrl_c(monkeypatch):
    naps = []

    def nap(seconds):
        naps.append(seconds)
        if len(naps) == 3:
            raise KeyboardInterrupt

    monkeypatch.setattr(rerun_io.time, "sleep", nap)
    rerun_io.serve_until_interrupted(poll_s=0.5)  # returns, does not raise
    assert naps == [0.5, 0.5, 0.5]


def test_serve_binds_localhost_and_prints_one_url(monkeypatch, caplog):
    """Without a display, mode 'rerun' serves the web viewer: a real Rerun server on 127.0.0.1
    only (never 0.0.0.0), at the URL returned, on a free port (--port 0)."""
    monkeypatch.setattr(rerun_io.sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)

    def no_spawn(self, **kw):
        raise AssertionError("spawned a viewer without a display")

    monkeypatch.setattr(rr.RecordingStream, "spawn", no_spawn)
    assert not rerun_io.has_display()
    try:
        rec, url = rerun_io.open_recording(name="x", mode="rerun", web_port=0)
        rec.log("hello", rr.TextDocument("hi"), static=True)
        m = re.fullmatch(r"http://127\.0\.0\.1:(\d+)/\?url=rerun%2Bhttp%3A%2F%2F127\.0\.0\.1"
                         r"%3A(\d+)%2Fproxy", url)
        assert m, url
        web, grpc = int(m.group(1)), int(m.group(2))
        (server,) = [psutil.Process(p.pid) for p in rerun_io._SERVERS]
        listening = {(c.laddr.ip, c.laddr.port)
                     for proc in (server, *server.children(recursive=True))
                     for c in proc.net_connections("tcp") if c.status == psutil.CONN_LISTEN}
        assert listening == {("127.0.0.1", web), ("127.0.0.1", grpc)}
        assert "no display" in caplog.text and url not in caplog.text  # the caller prints it
        # that port is now busy: a second viewer there is a one-line error before starting
        with pytest.raises(rerun_io.ViewModeError, match=f"port {web} is in use"):
            rerun_io.open_recording(name="y", mode="serve", web_port=web)
        assert len(rerun_io._SERVERS) == 1
    finally:
        rerun_io.stop_servers()
    assert not rerun_io._SERVERS
    monkeypatch.setenv("WAYLAND_DISPLAY", "wayland-0")
    assert rerun_io.has_display()


_LIMITED = """
import resource, sys
resource.setrlimit(resource.RLIMIT_FSIZE, (65536, 65536))
sys.argv = sys.argv[1:]
from {module} import main
main()
"""


@pytest.mark.parametrize(("module", "argv"), [
    ("groundstation.cli", ["groundstation", "plan", "show", "prbs-3axis", "--rrd"]),
])
def test_an_rrd_cut_short_by_the_file_size_limit_is_one_line_and_removed(tmp_path, module, argv):
    """Rerun's file writer only logs a failed write: the command printed a traceback (replay,
    plan show) or exited 0 (sysid --rrd) and left a cut-short .rrd."""
    import subprocess
    import sys

    path = tmp_path / "cut.rrd"
    done = subprocess.run([sys.executable, "-c", _LIMITED.format(module=module), *argv,
                           str(path)], capture_output=True, text=True, timeout=120)
    errors = [line for line in done.stderr.splitlines() if line.startswith("error:")]
    assert done.returncode == 2, done.stderr
    assert errors == [f"error: {str(path)!r} could not be written: File too large; nothing "
                      "was left"]
    assert "Traceback" not in done.stderr and not path.exists()


def test_a_failed_write_is_an_error_and_leaves_no_file(tmp_path, monkeypatch):
    path = tmp_path / "x.rrd"
    path.write_bytes(b"an older recording")
    rec, _ = rerun_io.open_recording(name="x", mode="save", rrd_path=path)
    rec.log("a/b", rr.TextDocument("hello"), static=True)
    real_replace = os.replace

    def full(src, dst):  # the disk filled as the file was completed
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", full)
    with pytest.raises(rerun_io.RecordingFileError, match="No space left on device") as info:
        rerun_io.close_file(rec, path)
    monkeypatch.setattr(os, "replace", real_replace)
    assert isinstance(info.value, OSError) and path.read_bytes() == b"an older recording"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.rrd"]  # no part file left


def test_closing_twice_or_discarding_never_writes_an_empty_file(tmp_path):
    path = tmp_path / "x.rrd"
    rec, _ = rerun_io.open_recording(name="x", mode="save", rrd_path=path)
    rec.log("a/b", rr.TextDocument("hello"), static=True)
    rerun_io.close_file(rec, path)
    size = path.stat().st_size
    rerun_io.close_file(rec, path)  # a second close (a finally clause) wrote 0 bytes over it
    assert path.stat().st_size == size > 0
    other = tmp_path / "y.rrd"
    rec, _ = rerun_io.open_recording(name="y", mode="save", rrd_path=other)
    rerun_io.discard_file(rec)
    rerun_io.close_file(rec, other)
    assert not other.exists()
