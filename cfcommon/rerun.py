"""Opening a Rerun recording: write an ``.rrd`` file, serve the web viewer, or spawn the viewer.

Both sides use it: the ground station's live view and replay (:mod:`groundstation.live`) and the
identification plots (:mod:`sysid.viz`). :func:`serve_until_interrupted` keeps a served viewer
up until Ctrl-C (``groundstation fly --view serve``, ``groundstation replay --view serve``).

Serving binds 127.0.0.1 only: the Rerun SDK's own servers listen on every interface (0.0.0.0)
with no option to change that, so :func:`serve_web` runs the Rerun viewer binary as a child
process, ``rerun --serve-web --bind 127.0.0.1``, and streams the recording to it.

Entity paths: every path either side logs to, and every path a blueprint names (a view's
``origin`` and its ``contents`` query expressions), is built by :func:`entity_path` from
unescaped parts, so that both name the same entity whatever the names hold. Panel titles go
through :func:`panel_title`, which keeps them short enough not to be cut in a small panel.
"""

from __future__ import annotations

import atexit
import logging
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Literal
from urllib.parse import quote

import rerun as rr

from cfcommon.cli import whole_file

__all__ = [
    "MODES",
    "TITLE_MAX",
    "WEB_PORT",
    "RecordingFileError",
    "ViewModeError",
    "check_port",
    "close_file",
    "discard_file",
    "entity_path",
    "has_display",
    "open_recording",
    "panel_title",
    "serve_until_interrupted",
    "serve_web",
    "stop_servers",
]

log = logging.getLogger(__name__)

MODES = ("rerun", "serve", "save")
"""``rerun``: native viewer (web viewer without a display); ``serve``: web viewer on
127.0.0.1 (:func:`serve_web`); ``save``: write an ``.rrd`` file."""

WEB_PORT = 9090


def entity_path(*parts: object, base: str = "/") -> str:
    """The absolute entity path of ``base`` followed by the unescaped ``parts``, each escaped.

    ``entity_path("stateEstimate+controller", "r_roll")`` is
    ``/stateEstimate\\+controller/r_roll``; ``entity_path("exp0", "gyro.x", base="/sysid")`` is
    ``/sysid/exp0/gyro.x``; ``entity_path()`` is the root ``/``. ``base`` is an entity path
    already (its ``/`` separate parts, nothing in it is escaped again).

    Rerun parses a logged path, a view's ``origin`` and each ``contents`` expression the same
    forgiving way: split at unescaped ``/``, undo ``\\`` escapes, keep any other character. So
    an unescaped ``+`` still names the same part, but a ``/`` in a name splits it, a ``\\``
    starts an escape, whitespace splits a query expression and ``$origin`` in a query is
    substituted. Escaping every part (:func:`rerun.escape_entity_path_part`) makes the logged
    string, the blueprint's strings and the path the file stores identical whatever the names
    hold. Parts are converted with ``str``; an empty part is a ``ValueError`` (Rerun would
    drop it and shift the path).
    """
    names = [str(p) for p in parts]
    if any(not n for n in names):
        raise ValueError(f"entity path parts must not be empty: {names!r}")
    head = base.strip("/")
    return "/" + "/".join([*([head] if head else []), *map(rr.escape_entity_path_part, names)])


TITLE_MAX = 20
"""Longest panel title: the viewer cuts longer ones in a small panel."""

_GROUP_PREFIX = re.compile(r"\b[A-Za-z_]\w*\.(?=\w)")  # "controller." of controller.r_roll


def panel_title(label: str, *, unit: str = "", max_len: int = TITLE_MAX) -> str:
    """``label [unit]`` in at most ``max_len`` characters, for a panel's title.

    Too long, the variable names in ``label`` lose their group (``controller.r_roll x
    motor.m1`` -> ``r_roll x m1``; the entity path keeps the full name); still too long, the
    label is cut and ends in ``…``, the unit kept. The unit (already short, ``deg/s``) is cut
    only when it alone leaves no room.
    """
    suffix = f" [{unit}]" if unit else ""
    for text in (label, _GROUP_PREFIX.sub("", label)):
        if len(text) + len(suffix) <= max_len:
            return text + suffix
    room = max_len - len(suffix) - 1
    if room < 3:
        return (text + suffix)[:max_len - 1] + "…"
    return text[:room] + "…" + suffix


class ViewModeError(ValueError):
    """An unknown view mode, ``save`` without a file, or a port that is taken (one line)."""


class RecordingFileError(OSError):
    """An ``.rrd`` file that could not be written (a full disk, ``ulimit -f``): one line naming
    the file and the reason; nothing of it is left (:func:`close_file`)."""

    def __str__(self) -> str:
        return f"{self.filename!r} could not be written: {self.strerror}; nothing was left"


#: The byte streams of the recordings opened in mode "save", by ``id`` of the recording.
_SAVING: dict[int, rr.BinaryStream] = {}


def close_file(rec: rr.RecordingStream, path: Path) -> None:
    """Write everything logged to ``rec`` (opened in mode ``"save"`` on ``path``) to ``path``.

    Rerun's own file writer (``RecordingStream.save``) reports a failed write only in its log:
    ``disconnect`` then keeps quiet about it (an ``.rrd`` cut short left behind, exit 0), or
    ``flush`` and ``disconnect`` wait forever (rerun 0.41, a full disk or ``ulimit -f``). So
    the recording goes to memory (``binary_stream``) and this writes it, beside ``path`` then
    renamed onto it: a file that cannot be written is a :class:`RecordingFileError` with the
    system's reason, and nothing of it is left. The whole recording is held in memory until
    then (an ``.rrd`` is about as large as the session it shows)."""
    stream = _SAVING.pop(id(rec), None)
    if stream is None:  # closed already, or never opened to be saved: nothing to write
        log.debug("close_file(%s): no recording to write", path)
        return
    data = stream.read(flush=True)
    rec.disconnect()
    try:
        with whole_file(Path(path)) as part:
            part.write_bytes(data or b"")
    except OSError as exc:
        raise RecordingFileError(exc.errno, exc.strerror, exc.filename) from None


def discard_file(rec: rr.RecordingStream) -> None:
    """Drop a recording opened in mode ``"save"`` without writing it (the work that was to
    fill it failed: no file rather than part of one)."""
    _SAVING.pop(id(rec), None)
    rec.disconnect()


def has_display() -> bool:
    """True when a native viewer can open a window (Linux: ``DISPLAY``/``WAYLAND_DISPLAY``)."""
    if sys.platform.startswith("linux"):
        return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
    return True


def open_recording(
    *,
    name: str,
    mode: Literal["rerun", "serve", "save"],
    rrd_path: Path | None = None,
    application_id: str = "cf-sysid",
    web_port: int = WEB_PORT,
) -> tuple[rr.RecordingStream, str | None]:
    """A new recording named ``name`` sent to a viewer or file; returns ``(recording, url)``.

    ``mode`` is one of :data:`MODES`. ``"rerun"`` spawns the native viewer when there is a
    display and otherwise serves the web viewer (logged warning). ``"serve"`` runs the web
    viewer on ``127.0.0.1:web_port`` (0: any free port, see :func:`serve_web`); ``url`` is its
    address, else None (the caller prints it). ``"save"`` needs ``rrd_path`` (its folder is
    created; an existing file is replaced when :func:`close_file` writes it).
    """
    if mode not in MODES:
        raise ViewModeError(f"view mode {mode!r} is unknown; use one of {', '.join(MODES)}")
    if mode == "save" and rrd_path is None:
        raise ViewModeError("view mode 'save' needs rrd_path; pass the .rrd file to write")
    if mode == "rerun" and not has_display():
        log.warning("no display (DISPLAY/WAYLAND_DISPLAY unset): serving the web viewer instead")
        mode = "serve"
    if mode == "serve":
        check_port(web_port)  # before anything starts: a busy port is a one-line error
    rec = rr.RecordingStream(application_id, recording_id=None)
    rec.send_recording_name(name)
    if mode == "save":  # written by close_file: rerun's file writer can hang on a full disk
        path = Path(rrd_path)  # type: ignore[arg-type]
        path.parent.mkdir(parents=True, exist_ok=True)
        _SAVING[id(rec)] = rec.binary_stream()
        log.info("recording for %s (written by close_file)", path)
        return rec, None
    if mode == "rerun":
        rec.spawn()
        return rec, None
    return rec, serve_web(rec=rec, web_port=web_port)


def check_port(port: int) -> None:
    """One-line :class:`ViewModeError` unless TCP ``port`` on 127.0.0.1 is free (0: any)."""
    if not 0 <= port <= 65535:
        raise ViewModeError(f"port {port} is out of range; use 1-65535, or 0 for any free port")
    if port and not _port_free(port):
        raise ViewModeError(f"port {port} is in use (another Rerun viewer?); pass --port with "
                             "a free port, or --port 0 for any free port")


def _port_free(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _listening(port: int) -> bool:
    try:
        with socket.create_connection(("127.0.0.1", port), timeout=0.5):
            return True
    except OSError:
        return False


_SERVERS: list[subprocess.Popen] = []
_RECORDINGS: list[rr.RecordingStream] = []


def stop_servers() -> None:
    """Stop the web viewers :func:`serve_web` started (also run at exit)."""
    while _RECORDINGS:  # cut the recordings loose first: no gRPC errors when it goes away
        rec = _RECORDINGS.pop()
        rec.flush()
        rec.disconnect()
    while _SERVERS:
        proc = _SERVERS.pop()
        for sig in (signal.SIGTERM, signal.SIGKILL):  # its own process group (and only it)
            try:
                os.killpg(proc.pid, sig)
            except (ProcessLookupError, PermissionError):
                break
            try:
                proc.wait(timeout=5.0)
                break
            except subprocess.TimeoutExpired:
                continue


def _die_with_parent() -> None:
    """In the child, Linux: SIGTERM when this process dies (even by SIGKILL, without atexit)."""
    if sys.platform.startswith("linux"):
        import ctypes

        ctypes.CDLL(None).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


def _rerun_executable() -> str:
    """The Rerun binary itself (not the ``rerun`` Python wrapper, which would outlive a
    terminate), else the ``rerun`` next to this Python, else ``rerun`` on PATH."""
    try:
        import rerun_cli  # the rerun-sdk's bundled viewer

        binary = Path(rerun_cli.__file__).with_name("rerun.exe" if os.name == "nt" else "rerun")
        if binary.is_file():
            return str(binary)
    except ImportError:
        pass
    script = Path(sys.executable).with_name("rerun")
    return str(script) if script.exists() else "rerun"


atexit.register(stop_servers)


def serve_web(*, rec: rr.RecordingStream, web_port: int = WEB_PORT,
              timeout_s: float = 30.0) -> str:
    """Serve ``rec`` to the Rerun web viewer on ``127.0.0.1:web_port``; returns its URL.

    The Rerun SDK's own servers listen on every interface (0.0.0.0) with no option to change
    that, so the viewer runs as a child process, ``rerun --serve-web --bind 127.0.0.1``
    (stopped at exit, or by :func:`stop_servers`); its gRPC port is any free port, and the
    recording streams to it. A busy ``web_port`` or a viewer that does not come up is a
    one-line :class:`ViewModeError`, raised before the caller starts any work.
    """
    check_port(web_port)
    web_port = web_port or _free_port()
    grpc_port = _free_port()
    command = [_rerun_executable(), "--serve-web", "--bind", "127.0.0.1",
               "--port", str(grpc_port), "--web-viewer-port", str(web_port),
               "--hide-welcome-screen"]
    try:
        proc = subprocess.Popen(command, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                stderr=subprocess.DEVNULL, start_new_session=True,
                                preexec_fn=_die_with_parent)
    except OSError as exc:
        raise ViewModeError(f"cannot start the Rerun web viewer ({command[0]}): "
                             f"{exc.strerror or exc}") from None
    _SERVERS.append(proc)
    deadline = time.monotonic() + timeout_s
    while not (_listening(grpc_port) and _listening(web_port)):
        if proc.poll() is not None or time.monotonic() > deadline:
            stop_servers()
            raise ViewModeError(f"the Rerun web viewer did not start on 127.0.0.1:{web_port} "
                                 "(port taken meanwhile?); pass --port 0 for any free port")
        time.sleep(0.05)
    grpc = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
    rec.connect_grpc(grpc)
    _RECORDINGS.append(rec)
    return f"http://127.0.0.1:{web_port}/?url={quote(grpc, safe='')}"


def serve_until_interrupted(*, poll_s: float = 1.0) -> None:
    """Block until Ctrl-C: the served web viewer lives in this process."""
    try:
        while True:
            time.sleep(poll_s)
    except KeyboardInterrupt:
        pass
