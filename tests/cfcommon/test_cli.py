"""The number type and output-path rule both command lines share (cfcommon/cli.py)."""

from __future__ import annotations

import os

import click
import pytest
from click.testing import CliRunner

from cfcommon.cli import FiniteFloat, check_output, whole_file


@click.command()
@click.option("--limit", type=FiniteFloat(min=1.0), default=None)
@click.option("--gap", type=FiniteFloat(min=0.0, min_open=True, max=10.0), default=None)
def _cmd(limit: float | None, gap: float | None) -> None:
    click.echo(f"{limit} {gap}")


@pytest.mark.parametrize(("args", "words"), [
    (["--limit", "nan"], "'nan' is not a finite number"),
    (["--limit", "inf"], "'inf' is not a finite number"),
    (["--limit", "-inf"], "not a finite number"),
    (["--limit", "0.5"], "0.5 is below 1"),
    (["--gap", "0"], "0 is not above 0"),
    (["--gap", "11"], "11 is above 10"),
    (["--gap", "x"], "'x' is not a number"),
])
def test_finite_float_refuses_nan_inf_and_out_of_range(args, words) -> None:
    res = CliRunner().invoke(_cmd, args)
    assert res.exit_code == 2 and words in res.output and "Traceback" not in res.output


def test_finite_float_accepts_numbers() -> None:
    res = CliRunner().invoke(_cmd, ["--limit", "300", "--gap", "1e-3"])
    assert res.exit_code == 0 and res.output.strip() == "300.0 0.001"


def test_check_output_rules(tmp_path) -> None:
    session = tmp_path / "flight.h5"
    session.write_bytes(b"flight data")
    view = tmp_path / "view.rrd"
    ok = check_output(view, option="--rrd", suffixes=(".rrd",), inputs=[session])
    assert ok == view
    cases = [
        (session, {"suffixes": (".rrd",)}, "must end in .rrd"),
        (session, {"suffixes": (".h5",), "inputs": [session], "overwrite": True},
         "is an input of this command"),
        (tmp_path / "pad.mat" / "v.rrd", {"suffixes": (".rrd",)}, "named like a file"),
        (session / "v.rrd", {"suffixes": (".rrd",)}, "is not a folder"),
        (tmp_path / "d.rrd", {"suffixes": (".rrd",)}, "is a folder"),
    ]
    (tmp_path / "d.rrd").mkdir()
    for path, kw, words in cases:
        with pytest.raises(click.BadParameter, match=words):
            check_output(path, option="--out", **kw)
    view.write_bytes(b"old view")
    with pytest.raises(click.BadParameter, match="already exists; pass --force"):
        check_output(view, option="--rrd", suffixes=(".rrd",), force_flag="--force")
    assert check_output(view, option="--rrd", suffixes=(".rrd",), overwrite=True) == view
    # the same file under another name is still the input
    link = tmp_path / "alias.h5"
    os.symlink(session, link)
    with pytest.raises(click.BadParameter, match="is an input"):
        check_output(link, option="--out", suffixes=(".h5",), inputs=[session], overwrite=True)
    assert session.read_bytes() == b"flight data"


def test_a_missing_folder_is_made_by_the_writer_not_the_check(tmp_path) -> None:
    """As ``groundstation import --out``: a missing folder is no refusal; the check makes
    nothing (a command failing later leaves no empty folder), the file's writer makes it."""
    out = tmp_path / "exp" / "deep" / "pad.mat"
    assert check_output(out, option="--out", suffixes=(".mat",)) == out
    assert not (tmp_path / "exp").exists()
    with whole_file(out) as part:
        part.write_bytes(b"mat")
    assert out.read_bytes() == b"mat"


@pytest.mark.skipif(os.geteuid() == 0, reason="root may write anywhere")
def test_check_output_refuses_read_only_folder(tmp_path) -> None:
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o500)
    with pytest.raises(click.BadParameter, match="not writable"):
        check_output(ro / "v.rrd", option="--rrd", suffixes=(".rrd",))
    with pytest.raises(click.BadParameter, match=f"{ro.name}' is not writable"):
        check_output(ro / "new" / "v.rrd", option="--rrd", suffixes=(".rrd",))


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="Linux's always-full device")
@pytest.mark.parametrize("argv", [["groundstation", "plan", "check", "hover-check"],
                                  ["sysid", "order", "--help"]])
def test_output_to_a_full_disk_is_one_line_and_exit_2(argv) -> None:
    """Standard output redirected to a full disk (``/dev/full``): one line on stderr and exit
    2, for a command's output and for click's own (``--help``; ``--version`` goes the same
    way, through the group's ``main``); it was a traceback and exit 1."""
    import subprocess
    import sys

    exe = os.path.join(os.path.dirname(sys.executable), argv[0])
    with open("/dev/full", "w") as full:
        done = subprocess.run([exe, *argv[1:]], stdout=full, stderr=subprocess.PIPE,
                              text=True, timeout=60)
    assert (done.returncode, done.stderr) == (2, "error: cannot write standard output: No "
                                                 "space left on device\n")


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="Linux's always-full device")
def test_standard_error_on_a_full_disk_too_keeps_exit_2() -> None:
    import subprocess
    import sys

    exe = os.path.join(os.path.dirname(sys.executable), "sysid")
    with open("/dev/full", "w") as full:
        done = subprocess.run([exe, "--version"], stdout=full, stderr=full, timeout=60)
    assert done.returncode == 2


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX file size limit (ulimit -f)")
def test_an_output_file_without_room_is_not_called_standard_output(tmp_path) -> None:
    """A file a command writes cut short by the disk (here ``ulimit -f``): one line naming an
    output file, not standard output (which the review found it named for both)."""
    import resource
    import subprocess
    import sys

    from tests.viz.sessions import write_session

    session = write_session(tmp_path / "flight.h5")
    (tmp_path / "out").mkdir()

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))

    exe = os.path.join(os.path.dirname(sys.executable), "groundstation")
    done = subprocess.run([exe, "export", str(session), "--to", "csv", "--out",
                           str(tmp_path / "out" / "csv")], capture_output=True, text=True,
                          timeout=120, preexec_fn=limit)
    assert (done.returncode, done.stderr) == (  # the file it stopped at, none left cut short
        2, f"error: cannot write {tmp_path / 'out' / 'csv' / 'acc.csv'}: File too large\n")


@pytest.mark.parametrize("argv", [["gs", "info", "LONG"], ["gs", "plan", "check", "LONG"],
                                  ["gs", "fly", "hover-check", "--out", "LONG"],
                                  ["sysid", "identify", "LONG"], ["sysid", "order", "LONG"]])
def test_a_file_name_too_long_is_one_line(argv) -> None:
    """A name past the file system's 255 characters: ``Path.exists()`` raises
    ENAMETOOLONG, which escaped as a traceback from every command taking a path."""
    from groundstation.cli import main as gs
    from sysid.cli import main as sysid_main

    long = "x" * 300
    res = CliRunner().invoke(gs if argv[0] == "gs" else sysid_main,
                             [long if a == "LONG" else a for a in argv[1:]])
    assert res.exit_code == 2, res.output
    assert res.output.strip().splitlines()[-1].startswith(
        "error: File name too long (300 characters): xxxx"), res.output


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX pipes and SIGPIPE's exit status")
@pytest.mark.parametrize("argv", [
    ["groundstation", "info", "SESSION"],  # rich's console (it exited 1 on its own)
    ["groundstation", "info", "SESSION", "--json"],  # click.echo
    ["groundstation", "--help"],  # click's help, before any sub-command
    ["sysid", "--version"],
    ["sysid", "identify", "--help"],
])
def test_a_pipe_whose_reader_quit_ends_the_command_as_it_ends_cat(argv, tmp_path) -> None:
    """``groundstation info S | head -1``: output into a pipe nobody reads any more exited 1
    (click's and rich's answer to EPIPE); ``cat``, ``seq`` and ``ls`` end with 141 (killed by
    SIGPIPE). Now both command lines do too, quietly: no traceback, no "Exception ignored" at
    the interpreter's exit. The pipe's reader is closed before the command starts, so its
    first write fails, whatever the timing."""
    import subprocess
    import sys

    from tests.viz.sessions import write_session

    session = write_session(tmp_path / "flight.h5")
    code = (f"import sys; from {argv[0]}.cli import main; sys.argv[0] = {argv[0]!r}; main()")
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-c", code,
                               *[str(session) if a == "SESSION" else a for a in argv[1:]]],
                              stdout=write, stderr=subprocess.PIPE, text=True, timeout=120,
                              cwd=root)
    finally:
        os.close(write)
    assert (done.returncode, done.stderr) == (141, "")  # 128 + SIGPIPE, as the shell says


_BUFFERED = """
import sys, click
from cfcommon.cli import OneLineErrorGroup
@click.group(cls=OneLineErrorGroup)
def g(): pass
@g.command()
def w():
    print("x" * 100)  # a plain print: still in the buffer when the command returns
g()
"""


@pytest.mark.skipif(not hasattr(os, "fork"), reason="POSIX pipes and SIGPIPE's exit status")
def test_output_still_buffered_when_the_command_ends_goes_the_same_way() -> None:
    """Output the command left in standard output's buffer failed only at the interpreter's
    exit: "Exception ignored ... BrokenPipeError" on stderr and exit 120. The group flushes it
    and ends as for any other write into the closed pipe."""
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    read, write = os.pipe()
    os.close(read)
    try:
        done = subprocess.run([sys.executable, "-c", _BUFFERED, "w"], stdout=write,
                              stderr=subprocess.PIPE, text=True, timeout=60, cwd=root, env=env)
    finally:
        os.close(write)
    assert (done.returncode, done.stderr) == (141, "")


def test_a_broken_pipe_that_is_no_output_stays_an_error() -> None:
    """Only standard output and error count as a reader gone: EPIPE from a socket (a Dask
    scheduler, a link) is an error of its own, never a quiet exit."""
    import socket

    from cfcommon.cli import reader_gone

    a, b = socket.socketpair()
    b.close()
    with a, pytest.raises(BrokenPipeError) as info:
        for _ in range(100):
            a.send(b"x" * 65536)
    assert not reader_gone(info.value)


_SOCKET_EPIPE = """
import socket, click
from cfcommon.cli import OneLineErrorGroup
@click.group(cls=OneLineErrorGroup)
def g(): pass
@g.command()
def w():
    a, b = socket.socketpair()
    b.close()
    for _ in range(100):
        a.send(b"x" * 65536)
g()
"""


def test_a_broken_pipe_that_is_no_output_is_one_line_not_a_silent_exit() -> None:
    """EPIPE from a socket went on up to click's ``main``, which takes any EPIPE for its
    output's reader gone: exit 1 and not a word. It is one line and exit 1."""
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    done = subprocess.run([sys.executable, "-c", _SOCKET_EPIPE, "w"], capture_output=True,
                          text=True, timeout=60, cwd=root)
    assert done.returncode == 1
    assert done.stderr.splitlines() == [
        "error: Broken pipe (BrokenPipeError): the other end of a connection or pipe the "
        "command writes to closed (not standard output's)"]


_FAILING_LISTENER = """
import sys
from groundstation.commands import fly
def rows(self, *, stream, rows):
    raise RuntimeError("progress broken")
fly.PlainProgress.rows = rows
from groundstation.cli import main
sys.argv[0] = "groundstation"
main()
"""


@pytest.mark.parametrize("verbose", [False, True])
def test_a_library_error_logged_in_a_command_is_one_line_unless_verbose(verbose, tmp_path):
    """A listener that raised (the progress display here) was logged by the runner with its
    full traceback on standard error, before the summary. A command's log is one line per
    record, the exception's type and text on it; ``-v`` adds the traceback."""
    import subprocess
    import sys

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    argv = [*(["-v"] if verbose else []), "fly", "hover-check", "--uri", "sim://71?speed=inf",
            "--out", str(tmp_path)]
    done = subprocess.run([sys.executable, "-c", _FAILING_LISTENER, *argv], cwd=root,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr  # the listener is dropped, the flight goes on
    failed = [line for line in done.stderr.splitlines() if "progress broken" in line]
    assert failed and failed[0].startswith("ERROR groundstation.flight" if verbose else
                                           "error: listener PlainProgress.rows failed")
    assert ("Traceback (most recent call last)" in done.stderr) is verbose
    if not verbose:
        assert failed[0].endswith("(RuntimeError: progress broken; -v shows the traceback)")


def test_a_log_record_stays_one_line_whatever_its_exception_says() -> None:
    """An exception whose text spans lines (a Dask or HDF5 error's often does) made the
    one-line record several lines; ``exc_info=True`` outside an except clause added
    "(NoneType: None; ...)"."""
    import logging

    from cfcommon.cli import _OneLineRecords

    fmt = _OneLineRecords(tracebacks=False)
    try:
        raise ValueError("first line\nsecond line")
    except ValueError:
        import sys

        record = logging.LogRecord("x", logging.ERROR, __file__, 1, "it failed", None,
                                   sys.exc_info())
    assert fmt.format(record) == ("error: it failed (ValueError: first line ...; -v shows "
                                  "the traceback)")
    bare = logging.LogRecord("x", logging.ERROR, __file__, 1, "no exception", None,
                             (None, None, None))
    assert fmt.format(bare) == "error: no exception"
    named = _OneLineRecords(tracebacks=True)  # -v: the module named, as logging does
    assert named.format(logging.LogRecord("x", logging.WARNING, __file__, 1, "w", None,
                                          None)) == "WARNING x: w"


def _raising(exc: BaseException) -> object:
    """A ``OneLineErrorGroup`` whose command ``read`` raises ``exc``; the result of running it."""
    from cfcommon.cli import OneLineErrorGroup

    @click.group(cls=OneLineErrorGroup)
    def group() -> None:
        pass

    @group.command()
    def read() -> None:
        raise exc

    return CliRunner().invoke(group, ["read"])


@pytest.mark.parametrize(("exc", "line"), [
    (OSError(5, "Input/output error", "/media/sd/log00"),
     "error: Input/output error (OSError): /media/sd/log00"),
    (NotADirectoryError(20, "Not a directory", "/etc/hostname/x.h5"),
     "error: Not a directory (NotADirectoryError): /etc/hostname/x.h5"),
    (ConnectionRefusedError(111, "Connection refused"),
     "error: Connection refused (ConnectionRefusedError)"),
])
def test_the_systems_refusal_is_one_line_and_exit_2(exc, line) -> None:
    """An ``OSError`` with an error number (a failing card, a read-only file system, a refused
    connection) is the system's answer, not a defect: it escaped as a traceback unless it was
    one of the few kinds named."""
    res = _raising(exc)
    assert res.exit_code == 2 and res.output.splitlines() == [line]


@pytest.mark.parametrize("exc", [
    OSError("Unable to synchronously open file (file signature not found)"),
    OSError(9, "Bad file descriptor"),
])
def test_an_oserror_the_system_did_not_refuse_is_no_user_error(exc) -> None:
    """One without an error number (a library's own ``OSError("...")``) or with one that says
    the command misused a call (EBADF, EINVAL) is no refusal of the system: it is left to the
    command's own handling, or shows as the defect it is."""
    res = _raising(exc)
    assert res.exit_code == 1 and isinstance(res.exception, OSError)
