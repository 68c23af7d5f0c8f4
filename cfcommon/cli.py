"""Command-line pieces shared by the ``sysid`` and ``groundstation`` commands.

* :class:`FiniteFloat`: a click number type that refuses ``nan`` and ``inf`` (click's
  ``FloatRange`` lets ``nan`` through every bound, which would switch a safety limit off).
* :func:`check_output`: the one rule for files a command writes. The suffix must be one the
  command writes, the folder must be writable (a missing one is made when the file is written,
  as ``groundstation import --out`` makes its folder: :func:`check_folder`), an input of the
  same command is never written over, and an existing file is replaced only when the caller
  allows it (``--force``).

Both raise :class:`click.BadParameter`, so each CLI prints one line and exits with 2.

* :func:`whole_file`: a file a command writes goes beside its name and is renamed onto it
  when complete, so a full disk or ``ulimit -f`` never leaves one cut short.

* :class:`OneLineErrorGroup`: the click group both CLIs use. A user error (a usage error, one
  of the group's ``user_errors``, a missing or unreadable file) prints ``error: ...`` on one
  line and exits with 2, never a traceback; ``-h`` still shows the usage. Ctrl-C prints one
  line and exits with 130 (click would print "Aborted!" and exit 1).

* :func:`output_gone`: the terminal closed (EIO) or a pipe's reader quit (EPIPE) under a
  command's output: what remains of it goes to the null device, so the command ends with its
  own exit status instead of a traceback.

* A pipe whose reader quit (``groundstation info S | head -1``) ends any command of either CLI
  as it ends ``cat`` or ``seq``: quietly, exit status :data:`READER_GONE` (141, the shell's
  number for a program SIGPIPE ended), no traceback and no "Exception ignored" at exit (the
  rest of the output goes to the null device). click exited 1, rich's console too.

* :func:`shown_text`: text from a file made elsewhere (a plan's phase names, a session's
  events, a path) as a terminal may be given it: control characters (``ESC [2J`` clears the
  screen, ``\r`` rewrites the line, a bell) written as Python escapes (``\x1b[2J``), so what
  is printed is what the file holds; :func:`shown_markup` for a rich console. The error line
  and every log record pass through it.

* :func:`output_console` and :func:`output_table`: text output that fits where it goes. On a
  terminal, rich tables at the terminal's width (or ``--width``); piped (``| cat``, a file),
  plain tables, no colour, never wrapped (a line is as long as its content, or ``--width``),
  and no trailing spaces (a plain table pads its last column to the widest cell).
"""

from __future__ import annotations

import contextlib
import errno
import io
import logging
import math
import os
import re
import select
import signal
import stat
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, ClassVar, NoReturn

import click
from rich.console import Console
from rich.markup import escape
from rich.table import Table

__all__ = ["DEFAULT_INPUTS", "DEFAULT_OUTPUTS", "NO_ROOM", "READER_GONE", "FiniteFloat",
           "OneLineErrorGroup", "check_folder", "check_output", "drop_failing_stdout",
           "end_reader_gone", "names_a_file",
           "output_console", "output_gone", "output_table", "reader_gone", "same_file_pairs",
           "setup_logging", "shown_markup", "shown_text", "whole_file", "writing_stdout"]

#: The channels both command lines take from a session by default: ``sysid``'s commands and
#: ``groundstation export --to mat`` (so MATLAB gets the data sysid identifies from). Firmware
#: variables, not stream names: ``motor.m1..m4`` in a flight's ``motors`` stream, a cfclient
#: CSV's ``Motors`` and a uSD log alike (``motors`` named a flight's stream only; the group
#: ``motor`` also holds ``m1req..m4req`` where those are logged).
DEFAULT_INPUTS = "motor.m1,motor.m2,motor.m3,motor.m4"
DEFAULT_OUTPUTS = "acc.z,gyro"

_UNWRAPPED = 100_000  # a console width no line reaches: piped output is never wrapped

#: What :func:`shown_text` escapes: C0 controls (tab and line feed too: one name, one line),
#: DEL, C1 controls (``\x9b`` is a CSI on some terminals), the line and paragraph separators
#: and the bidirectional overrides and isolates (they reorder the text shown after them).
_UNSHOWN = re.compile("[\x00-\x1f\x7f-\x9f\u2028\u2029\u200e\u200f\u202a-\u202e"
                      "\u2066-\u2069]")


def shown_markup(text: object) -> str:
    """:func:`shown_text` for a rich console: also ``[`` escaped, so ``[/x]`` in a file's text
    is printed, not taken for markup."""
    return escape(shown_text(text))


def shown_text(text: object) -> str:
    """``text`` (``str()`` of it) with every control character written as Python writes it in
    a string's repr (``\x1b``, ``\r``, ``\n``, ``\u202e``); the rest unchanged (no quotes,
    backslashes as they are: a Windows path stays readable)."""
    return _UNSHOWN.sub(lambda m: repr(m.group())[1:-1], str(text))


#: What a write gets when the disk, a quota or ``ulimit -f`` has no room for it (also standard
#: output redirected to a full disk or ``/dev/full``).
NO_ROOM = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
#: Error numbers by which the system refuses what a command asked (a failing card, a read-only
#: file system, a path through a file, too many open files, a device gone, a peer that refuses
#: or drops a connection): one line each (:meth:`OneLineErrorGroup.user_error_message`).
REFUSALS = frozenset({
    errno.EIO, errno.EROFS, errno.ENOTDIR, errno.ELOOP, errno.EMFILE, errno.ENFILE,
    errno.EBUSY, errno.ETXTBSY, errno.ENODEV, errno.ENXIO, errno.EEXIST, errno.ENOTEMPTY,
    errno.ECONNREFUSED, errno.ECONNRESET, errno.ECONNABORTED, errno.ETIMEDOUT,
    errno.EHOSTUNREACH, errno.ENETUNREACH, errno.EADDRINUSE, errno.EADDRNOTAVAIL})


#: The exit status of a command whose output pipe's reader quit (``| head``): 128 + SIGPIPE,
#: what the shell reports for ``cat``, ``seq`` or ``ls`` cut short the same way (they die of
#: the signal; Python ignores it and gets EPIPE instead).
READER_GONE = 128 + getattr(signal, "SIGPIPE", 13)


def reader_gone(exc: BaseException) -> bool:
    """True when ``exc`` is EPIPE from writing standard output or error, not a socket's (a
    Dask scheduler, a link): the reader of the pipe quit. Told by the write that raised it
    (:func:`writing_stdout`) or, for a write this cannot see (``print``, ``sys.stdout.write``
    in a command), by the pipe itself (:func:`_pipe_reader_quit`)."""
    return (isinstance(exc, OSError) and exc.errno == errno.EPIPE
            and (writing_stdout(exc, stderr=True)
                 or _pipe_reader_quit(sys.stdout) or _pipe_reader_quit(sys.stderr)))


def _pipe_reader_quit(stream: Any) -> bool:
    """Whether ``stream`` writes into a pipe nobody reads any more: poll reports an error on
    its end (False where that cannot be known: no file descriptor, no ``poll``)."""
    try:
        fd = stream.fileno()
        if not stat.S_ISFIFO(os.fstat(fd).st_mode):
            return False
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        return any(events & select.POLLERR for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):  # io.UnsupportedOperation is both
        return False


def end_reader_gone() -> NoReturn:
    """End the command quietly with :data:`READER_GONE`, the standard streams pointed at the
    null device first: the interpreter's flush at exit then has nowhere to fail (Python's
    recipe, the ``signal`` module's note on SIGPIPE)."""
    _to_null(1, 2)
    sys.exit(READER_GONE)


@contextlib.contextmanager
def _quiet_when_reader_gone() -> Iterator[None]:
    """A pipe whose reader quit ends the command quietly (:func:`end_reader_gone`); any other
    EPIPE (a socket's, a pipe to a child process) is an error of its own: one line and exit
    status 1 (click's ``main`` would end it with exit 1 and not a word)."""
    try:
        yield
    except OSError as exc:
        if reader_gone(exc):
            end_reader_gone()
        if exc.errno != errno.EPIPE:
            raise
        _say(f"error: {exc.strerror or 'Broken pipe'} ({type(exc).__name__}): the other end "
             "of a connection or pipe the command writes to closed (not standard output's)")
        sys.exit(1)


def _flush_stdout() -> None:
    """``sys.stdout.flush()``, the stream a local (:func:`writing_stdout` knows it failed)."""
    out = sys.stdout
    if out is not None:
        out.flush()


class _OneLineRecords(logging.Formatter):
    """Each log record one line, ``warning: message`` as the commands' own warnings are
    (``LEVEL logger: message``, naming the module, with ``tracebacks``: ``-v``); a record with
    an exception gets its type and text on that line, and its traceback only with
    ``tracebacks``."""

    def __init__(self, *, tracebacks: bool) -> None:
        super().__init__("%(levelname)s %(name)s: %(message)s" if tracebacks
                         else "%(level)s: %(message)s")
        self.tracebacks = tracebacks

    def format(self, record: logging.LogRecord) -> str:
        record.level = record.levelname.lower()
        return self._format(record)

    def formatMessage(self, record: logging.LogRecord) -> str:
        """The record's line, control characters escaped (:func:`shown_text`): a message
        quoting a file's text is one line and changes nothing on the terminal."""
        return shown_text(super().formatMessage(record))

    def _format(self, record: logging.LogRecord) -> str:
        if self.tracebacks or not record.exc_info:
            return super().format(record)
        exc = record.exc_info[1]
        saved = record.exc_info, record.exc_text, record.stack_info
        record.exc_info = record.exc_text = record.stack_info = None
        try:
            text = super().format(record)
        finally:
            record.exc_info, record.exc_text, record.stack_info = saved
        if exc is None:  # exc_info=True outside an except clause: nothing to show
            return text
        lines = str(exc).splitlines()  # an exception's text may span lines: its first
        what = shown_text(f"{lines[0]} ..." if len(lines) > 1 else "".join(lines))
        return f"{text} ({type(exc).__name__}: {what}; -v shows the traceback)"


def setup_logging(*, verbose: int) -> None:
    """The command lines' logging on standard error: warnings and errors (``-v`` info, ``-vv``
    debug), one line each; tracebacks only from ``-v`` on (a library's ``log.exception`` is
    no traceback for the user of a command)."""
    handler = logging.StreamHandler()
    handler.setFormatter(_OneLineRecords(tracebacks=verbose >= 1))
    logging.basicConfig(level=logging.WARNING - 10 * min(verbose, 2), handlers=[handler])


def drop_failing_stdout() -> None:
    """Point standard output at the null device when what it holds cannot be written (a full
    disk under a redirection): the interpreter's flush at exit then does not fail again with
    a second message. Output that can still be written is flushed first."""
    try:
        sys.stdout.flush()
    except OSError:
        _to_null(1)


def _to_null(*fds: int) -> None:
    """Point the file descriptors ``fds`` at the null device (errors ignored)."""
    with contextlib.suppress(OSError):
        null = os.open(os.devnull, os.O_WRONLY)
        for fd in fds:
            with contextlib.suppress(OSError):
                os.dup2(null, fd)
        os.close(null)


def writing_stdout(exc: BaseException, *, stderr: bool = False) -> bool:
    """Whether ``exc`` was raised writing standard output (or error too, with ``stderr``):
    the innermost Python frame of its traceback holds ``sys.stdout`` (``click.echo``'s
    ``file``) or is this module's stdout wrapper (rich's console writes through it)."""
    tb = exc.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    return any(v is sys.stdout or (stderr and v is sys.stderr)
               or (isinstance(v, _TrimmedLines) and (stderr or not v._stderr))
               for v in tb.tb_frame.f_locals.values())


def output_gone(exc: BaseException) -> bool:
    """True when ``exc`` (raised writing to stdout or stderr) says the output has nowhere to go:
    EIO (the terminal closed: a hang-up) or EPIPE (the reader of a pipe quit). Standard output
    is then pointed at the null device, and so is standard error unless it still works (it
    goes elsewhere: ``fly | head -1`` on a terminal keeps the error line that says how the
    flight ended), so later writes (the error line, logging, the interpreter's flush at exit)
    neither fail nor print a traceback."""
    if not isinstance(exc, OSError) or exc.errno not in (errno.EIO, errno.EPIPE):
        return False
    _to_null(*((1,) if _stderr_elsewhere() else (1, 2)))
    return True


def _stderr_elsewhere() -> bool:
    """Whether standard error is another file than standard output (not the same terminal or
    pipe) and, if a pipe, one still read."""
    try:
        out, err = os.fstat(1), os.fstat(2)
    except OSError:
        return False
    return ((out.st_dev, out.st_ino) != (err.st_dev, err.st_ino)
            and not _pipe_reader_quit(sys.stderr))


class _TrimmedLines(io.TextIOBase):
    """The standard stream (looked up at each write, so a redirection in between is followed)
    with each complete line's trailing spaces removed; a partial line waits for its end."""

    def __init__(self, *, stderr: bool) -> None:
        self._stderr, self._pending = stderr, ""

    def _stream(self) -> Any:
        return sys.stderr if self._stderr else sys.stdout

    def writable(self) -> bool:
        return True

    def isatty(self) -> bool:
        return False

    def write(self, text: str) -> int:
        *lines, self._pending = (self._pending + text).split("\n")
        if lines:
            self._stream().write("".join(line.rstrip(" ") + "\n" for line in lines))
        return len(text)

    def flush(self) -> None:
        if self._pending:  # print(end=""): a line that may go on, written as it is
            self._stream().write(self._pending)
            self._pending = ""
        self._stream().flush()


class _Console(Console):
    """rich's console, but a pipe whose reader quit ends the command as any other output does
    (:func:`end_reader_gone`); rich's own answer is exit 1."""

    def on_broken_pipe(self) -> None:
        self.quiet = True
        end_reader_gone()


def output_console(*, width: int | None = None, stderr: bool = False) -> Console:
    """The console for a command's text output (module docstring); ``width`` in characters."""
    if Console(stderr=stderr).is_terminal:
        return _Console(highlight=False, width=width, stderr=stderr)
    return _Console(file=_TrimmedLines(stderr=stderr), highlight=False,
                    width=width or _UNWRAPPED, no_color=True, soft_wrap=width is None)


def output_table(*columns: str, console: Console, title: str | None = None) -> Table:
    """A table drawn with box lines on a terminal, and plain (columns separated by two
    spaces, one header line) when piped."""
    columns = tuple(escape(c) for c in columns)  # "fields [unit]" is a title, not markup
    if console.is_terminal:
        return Table(*columns, title=title)
    return Table(*columns, title=title, box=None, pad_edge=False, padding=(0, 2, 0, 0),
                 title_justify="left")


class FiniteFloat(click.ParamType):
    """A finite float within optional bounds: ``FiniteFloat(min=0.5)``, ``min_open=True`` for
    ``> min``."""

    name = "float"

    def __init__(self, *, min: float | None = None, max: float | None = None,
                 min_open: bool = False) -> None:
        self.min, self.max, self.min_open = min, max, min_open

    def convert(self, value: object, param: click.Parameter | None,
                ctx: click.Context | None) -> float:
        try:
            x = float(value)  # type: ignore[arg-type]
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(x):
            self.fail(f"{value!r} is not a finite number", param, ctx)
        if self.min is not None and (x <= self.min if self.min_open else x < self.min):
            self.fail(f"{x:g} is {'not above' if self.min_open else 'below'} {self.min:g}",
                      param, ctx)
        if self.max is not None and x > self.max:
            self.fail(f"{x:g} is above {self.max:g}", param, ctx)
        return x

    def get_metavar(self, param: click.Parameter, ctx: click.Context | None = None) -> str:
        lo = "" if self.min is None else f"{'>' if self.min_open else '>='}{self.min:g}"
        hi = "" if self.max is None else f"<={self.max:g}"
        return f"FLOAT {' '.join(s for s in (lo, hi) if s)}".strip()


def check_output(path: Path, *, option: str, suffixes: Sequence[str],
                 inputs: Sequence[Path] = (), overwrite: bool = False,
                 force_flag: str | None = None) -> Path:
    """Return ``path`` if a command may write it; otherwise raise a one-line ``BadParameter``.

    ``suffixes`` are the allowed endings (``(".rrd",)``); ``inputs`` the files the command
    reads (never written over, whatever ``overwrite`` says); ``overwrite`` allows replacing an
    existing output; ``force_flag`` names the flag that would allow it, for the message. A
    missing folder is not made here (a command refused later leaves none behind): the writer
    makes it (:func:`whole_file` does), just before it writes.
    """
    path = Path(path)
    if path.suffix.lower() not in {s.lower() for s in suffixes}:
        raise click.BadParameter(f"{str(path)!r} must end in {' or '.join(suffixes)}",
                                 param_hint=option)
    for src in inputs:
        if _same_file(path, Path(src)):
            raise click.BadParameter(f"{str(path)!r} is an input of this command; write the "
                                     "output to another file", param_hint=option)
    check_folder(path.parent, option=option)
    if path.is_dir():
        raise click.BadParameter(f"{str(path)!r} is a folder; give a file name",
                                 param_hint=option)
    if path.exists() and not path.is_file():  # a FIFO waited for a reader, Ctrl-C ignored
        raise click.BadParameter(f"{str(path)!r} is not a regular file (a FIFO, a device or a "
                                 "socket); give a file name", param_hint=option)
    if path.exists() and not overwrite:
        how = f"pass {force_flag} to replace it or " if force_flag else ""
        raise click.BadParameter(f"{str(path)!r} already exists; {how}choose another name",
                                 param_hint=option)
    return path


def check_folder(folder: Path, *, option: str) -> Path:
    """Return ``folder`` if a command may write into it, also when missing (its writer makes
    it, as ``groundstation import --out`` makes its folder: :func:`whole_file`); otherwise
    raise a one-line ``BadParameter``.

    Nothing is made here: the folder's nearest existing ancestor must be a writable folder,
    and no missing part of it may be named like a file (``--out pad.mat/x.mat``: a folder
    ``pad.mat`` is a slip, which the next command would refuse)."""
    folder = Path(folder)
    existing = folder
    while not existing.exists() and existing != existing.parent:
        if names_a_file(existing):
            raise click.BadParameter(
                f"folder {str(existing)!r} does not exist and is named like a file, so it is "
                "not made; give the file name after an existing or plain folder name",
                param_hint=option)
        existing = existing.parent
    if not existing.is_dir():
        raise click.BadParameter(f"{str(existing)!r} is not a folder", param_hint=option)
    if not os.access(existing, os.W_OK | os.X_OK):
        raise click.BadParameter(f"folder {str(existing)!r} is not writable",
                                 param_hint=option)
    return folder


#: Endings of the files the two command lines read and write: a folder option (``--out`` of
#: ``fly``, ``import``, ``demo``, ``export --to csv|parquet``, ``sysid batch``) given a name
#: with one of them names a file where a folder is meant (:func:`names_a_file`).
FILE_SUFFIXES = (".h5", ".hdf5", ".json", ".mat", ".csv", ".parquet", ".rrd", ".toml", ".txt",
                 ".bin")


def names_a_file(folder: Path) -> bool:
    """True when ``folder``, which a command would create as a folder, does not exist and
    ends in one of :data:`FILE_SUFFIXES` (``--out model.h5`` where models go into a folder):
    made, it would be a folder named like a file, which the next command then refuses."""
    folder = Path(folder)
    return not folder.exists() and folder.suffix.lower() in FILE_SUFFIXES


@contextlib.contextmanager
def whole_file(path: Path) -> Iterator[Path]:
    """The name to write ``path``'s content to, beside it; renamed onto ``path`` once written,
    removed if writing failed. A missing folder of ``path`` is made first (:func:`check_folder`
    allowed it). The ``OSError`` then names ``path`` (the file the command stopped at),
    whatever name failed underneath."""
    path = Path(path)
    part = path.with_name(f".{path.name}.{os.getpid()}.part")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield part
        os.replace(part, path)
    except OSError as exc:
        raise OSError(exc.errno or errno.EIO, exc.strerror or "write failed", str(path)) \
            from None
    finally:
        with contextlib.suppress(OSError):
            part.unlink()


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def same_file_pairs(paths: Sequence[Path], others: Sequence[Path] | None = None
                    ) -> list[tuple[Path, Path]]:
    """``(a, b)`` for each two of ``paths`` that name one file (as given twice, or through a
    link or another spelling of its path), or, with ``others``, for each of ``paths`` that is
    also one of ``others``: the same session read twice (``sysid identify A A``, ``identify A
    --validate A``) is the same data, whatever the command then does with it."""
    paths = [Path(p) for p in paths]
    if others is None:
        return [(a, b) for i, a in enumerate(paths) for b in paths[i + 1:] if _same_file(a, b)]
    return [(a, Path(b)) for a in paths for b in others if _same_file(a, Path(b))]


class OneLineErrorGroup(click.Group):
    """A click group whose user errors print one line and exit 2, never a traceback.

    Subclasses name their own exception trees in ``user_errors`` (printed whole, control
    characters escaped: a name quoted in it may hold a line feed)
    and may add messages for other exceptions in :meth:`user_error_message`. ``sysid X`` alone
    (no arguments) still shows X's help.
    """

    user_errors: ClassVar[tuple[type[BaseException], ...]] = ()

    def user_error_message(self, exc: Exception, *, ctx: click.Context) -> str | None:
        """The one line for ``exc``, or None when it is not a user error (it propagates)."""
        if isinstance(exc, click.UsageError):
            if isinstance(exc, click.exceptions.NoArgsIsHelpError):
                return None
            where = exc.ctx.command_path if exc.ctx is not None else ctx.command_path
            if isinstance(exc, click.NoSuchOption) and exc.ctx is not None \
                    and exc.ctx.command is not self and exc.option_name in {
                        o for p in self.params for o in p.opts}:  # -v after the command
                return (f"{exc.option_name} is an option of '{ctx.command_path}', given before "
                        f"the command: {ctx.command_path} {exc.option_name} "
                        f"{exc.ctx.info_name} ...")
            # click puts a required choice's values on lines of their own ("Missing option
            # '--format'. Choose from:\n\tjson,\n\tmat"): one line, as every error here
            return f"{' '.join(exc.format_message().split())} (see '{where} -h')"
        if isinstance(exc, self.user_errors):  # one line by construction; a file's name in
            return str(exc) or type(exc).__name__  # it may hold a line feed: _say escapes it
        if isinstance(exc, FileNotFoundError | PermissionError | IsADirectoryError):
            return f"{exc.strerror}: {exc.filename}"
        if isinstance(exc, OSError) and exc.errno == errno.ENAMETOOLONG:
            name = str(exc.filename or "")
            shown = name if len(name) <= 80 else f"{name[:60]}...{name[-12:]}"
            return f"{exc.strerror} ({len(name)} characters): {shown}"
        if isinstance(exc, OSError) and exc.errno in REFUSALS:
            # the system's refusal, no defect of the command (EBADF, EINVAL ... would be one
            # and stay a traceback); -vv shows where
            logging.getLogger(__name__).debug("%s", exc, exc_info=exc)
            where = f": {exc.filename}" if exc.filename else ""
            return f"{exc.strerror or os.strerror(exc.errno)} ({type(exc).__name__}){where}"
        return None

    def main(self, *args: Any, **kwargs: Any) -> Any:
        """click's ``main``; a write refused for want of room (standard output redirected to a
        full disk or ``/dev/full``, ``--help`` included) is one line and exit status 2; a pipe
        whose reader quit ends it quietly with :data:`READER_GONE`. What standard output still
        buffers when the command ends is written here, so that either shows here too, not at
        the interpreter's exit ("Exception ignored ... BrokenPipeError", exit 120)."""
        try:
            try:
                return super().main(*args, **kwargs)
            finally:  # also when click's standalone main ends with SystemExit, as it does
                _flush_stdout()
        except OSError as exc:
            if reader_gone(exc):
                end_reader_gone()
            if exc.errno not in NO_ROOM:
                raise
            drop_failing_stdout()
            where = (exc.filename if exc.filename else "standard output"
                     if writing_stdout(exc) else "an output file (it may be cut short)")
            _say(f"error: cannot write {where}: {exc.strerror}")
            sys.exit(2)

    def make_context(self, *args: Any, **kwargs: Any) -> click.Context:
        with _quiet_when_reader_gone():  # the group's own --help and --version (click: exit 1)
            return super().make_context(*args, **kwargs)

    def invoke(self, ctx: click.Context) -> Any:
        try:
            with _quiet_when_reader_gone():
                return super().invoke(ctx)
        except KeyboardInterrupt:  # Ctrl-C: one line and the shell's code for SIGINT
            _say("error: interrupted (Ctrl-C)")
            sys.exit(130)
        except Exception as exc:  # click's Exit and Abort are not user errors: they propagate
            msg = self.user_error_message(exc, ctx=ctx)
            if msg is None:
                raise
        _say(f"error: {msg}")
        sys.exit(2)


def _say(line: str) -> None:
    """The error line on stderr; a terminal or pipe that is gone takes nothing (the exit status
    still tells)."""
    try:
        click.echo(shown_text(line), err=True)
    except OSError as exc:
        if not output_gone(exc) and exc.errno not in NO_ROOM:
            raise
