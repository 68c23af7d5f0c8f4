"""The commands the README and docs/*.md show are real: every ``groundstation``/``sysid`` line
of their shell blocks parses against the command line as it is (sub-command, options, values),
and the ones that need no hardware, viewer, network or long run are run, in a scratch folder
holding the files the examples name (``flight.h5``, ``sessions/prbs-3axis-A.h5`` and ``-B``),
and must succeed. Every Python block imports real names from their current paths, and runs there
as written, given only the names the text around it defines (the flight data ``u``, ``y``,
``data``, ``val``)."""

from __future__ import annotations

import ast
import builtins
import glob
import importlib
import re
import shlex
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

import groundstation.sim as gsim
from groundstation.cli import main as gs_main
from sysid.cli import main as sysid_main
from tests.sysid.flights import known_system, write_flight
from tests.test_old_paths import MOVED
from tests.viz.sessions import write_session

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
MAINS = {"groundstation": gs_main, "sysid": sysid_main}
_FENCE = re.compile(r"^```(\w*)\s*$")


def commands(path: Path) -> list[list[str]]:
    """Command lines (as argv) of the shell blocks of ``path``; ``a & b`` gives two."""
    out, lang = [], None
    for line in path.read_text().splitlines():
        m = _FENCE.match(line.strip())
        if m:
            lang = None if lang is not None else m.group(1)
            continue
        if lang not in ("", "sh", "bash", "shell", "console"):
            continue
        for part in line.split(" & "):
            if part.strip().split(" ", 1)[0] in MAINS:
                out.append(shlex.split(part, comments=True))
    return out


ALL = [(p.name, argv) for p in DOCS for argv in commands(p)]


def _runnable(argv: list[str]) -> bool:
    """Needs no hardware, viewer, network or long run: decided by what the command does."""
    words = argv[:3]
    if "--help" in argv or "--view" in argv:
        return False
    if words[:2] == ["groundstation", "fly"]:
        uri = argv[argv.index("--uri") + 1] if "--uri" in argv else ""
        return uri.startswith("sim://") and argv[2] == "hover-check"
    if words[:2] == ["groundstation", "replay"]:
        return "--rrd" in argv  # otherwise it opens a viewer
    return words[:2] in (["groundstation", "plan"], ["groundstation", "info"],
                         ["groundstation", "export"],
                         ["sysid", "order"], ["sysid", "identify"], ["sysid", "compare"],
                         ["sysid", "export"])


def _parse(argv: list[str]) -> None:
    """Parse ``argv`` as the CLI would, without running it (unknown options, bad values and
    missing sub-commands raise)."""
    if "--help" in argv:  # harmless: run it
        res = CliRunner().invoke(MAINS[argv[0]], argv[1:])
        assert res.exit_code == 0 and "Usage" in res.output, res.output
        return
    cmd: click.Command = MAINS[argv[0]]
    ctx = click.Context(cmd, info_name=argv[0])
    rest = argv[1:]
    while isinstance(cmd, click.Group):
        name, sub, rest = cmd.resolve_command(ctx, rest)
        assert sub is not None, argv
        cmd = sub
        ctx = click.Context(cmd, parent=ctx, info_name=name)
    cmd.make_context(ctx.info_name, list(rest), parent=ctx.parent)


def help_examples() -> list[tuple[str, list[str]]]:
    """``(command, argv)`` of every command line in the --help of every sub-command of both
    CLIs (a line ending in a backslash continues; ``| jq ...`` and comments cut off)."""
    out = []

    def walk(cmd: click.Command, ctx: click.Context) -> None:
        if isinstance(cmd, click.Group):
            for name in cmd.list_commands(ctx):
                sub = cmd.get_command(ctx, name)
                walk(sub, click.Context(sub, parent=ctx, info_name=name))
            return
        line = ""
        for text in (cmd.help or "").splitlines():
            text = text.strip()
            if not line and text.split(" ", 1)[0] not in MAINS:
                continue
            line = f"{line} {text}".strip()
            if line.endswith("\\"):
                line = line[:-1]
                continue
            argv = shlex.split(line, comments=True)
            out.append((ctx.command_path, argv[:argv.index("|")] if "|" in argv else argv))
            line = ""

    for name, main in MAINS.items():
        walk(main, click.Context(main, info_name=name))
    return out


HELP = help_examples()


def test_the_help_shows_commands():
    assert {"groundstation demo", "groundstation info", "sysid batch"} <= {c for c, _ in HELP}


@pytest.mark.parametrize(("where", "argv"), [
    *((d, a) for d, a in ALL if any("*" in x for x in a)),
    *((f"{c} --help", a) for c, a in HELP if any("*" in x for x in a))],
    ids=lambda v: v if isinstance(v, str) else " ".join(v)[:60])
def test_a_pattern_in_an_example_still_runs_when_it_matches_several_files(where, argv):
    """`groundstation info demo-out/prbs-3axis-*.h5` (demo's --help) and the README's
    `info sessions/hover-check-*.h5` failed with "Got unexpected extra argument" as soon as
    two files matched (the demo records two; every flight is a new file): a pattern belongs
    only where the command takes several files."""
    several = [name for arg in argv
               for name in ([arg.replace("*", "1", 1), arg.replace("*", "2", 1)]
                            if "*" in arg else [arg])]
    _parse(several)


def test_a_uri_with_a_query_is_quoted_in_the_docs():
    """zsh (macOS's login shell) takes an unquoted `?` for a file pattern: `--uri
    sim://0?speed=20 --live-id` (docs/live-id.md) ended in "zsh: no matches found" before the
    command ran; the README and docs/flying.md quote it."""
    bare = []
    for doc in DOCS:
        lang = None
        for line in doc.read_text().splitlines():
            m = _FENCE.match(line.strip())
            if m:
                lang = None if lang is not None else m.group(1)
                continue
            if lang in ("", "sh", "bash", "shell", "console") and \
                    line.strip().split(" ", 1)[0] in MAINS:
                bare += [(doc.name, w) for w in line.split()
                         if "://" in w and "?" in w and w[0] not in "'\""]
    assert not bare, bare


def test_the_docs_say_what_ctrl_c_does():
    """Ctrl-C prints `error: interrupted (Ctrl-C)` and exits 130 on both CLIs
    (cfcommon.cli.OneLineErrorGroup); docs/sysid.md said a sweep printed click's `Aborted!`
    and exited 1."""
    for doc in DOCS:
        assert "Aborted!" not in doc.read_text(), doc.name
    text = " ".join((ROOT / "docs" / "sysid.md").read_text().split())
    assert ("Ctrl-C stops a parallel sweep at once: pending pairs are cancelled and the "
            "workers (which ignore SIGINT themselves) terminated; the command prints "
            "`error: interrupted (Ctrl-C)` and exits with 130") in text


def test_the_docs_show_commands():
    names = {argv[1] for _, argv in ALL}
    assert {"fly", "info", "replay", "export", "identify", "compare", "order", "sweep"} <= names
    assert sum(_runnable(argv) for _, argv in ALL) >= 15


@pytest.mark.parametrize(("doc", "argv"), ALL, ids=[f"{d}: {' '.join(a)[:60]}" for d, a in ALL])
def test_documented_command_parses(doc, argv):
    _parse(argv)


@pytest.fixture(scope="module")
def scratch(tmp_path_factory):
    d = tmp_path_factory.mktemp("docs")
    (d / "sessions").mkdir()
    system = known_system()
    for name, seed in (("A", 1), ("B", 2)):
        write_flight(d / "sessions" / f"prbs-3axis-{name}.h5", system=system, seed=seed)
    write_session(d / "flight.h5")
    # the README's name for "the file fly printed" (a flight's file is named by its start)
    write_session(d / "sessions" / "hover-check-20261122T100000Z.h5")
    return d


@pytest.mark.parametrize("doc", [p for p in DOCS if any(_runnable(a) for a in commands(p))],
                         ids=lambda p: p.name)
def test_documented_commands_run(doc, scratch, tmp_path, monkeypatch):
    """Each doc's runnable examples, in order, in a copy of the scratch folder."""
    for f in scratch.rglob("*.h5"):
        target = tmp_path / f.relative_to(scratch)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(f.read_bytes())
    monkeypatch.chdir(tmp_path)
    ran = 0
    try:
        for argv in commands(doc):
            if not _runnable(argv):
                continue
            args = [a for arg in argv[1:]
                    for a in (sorted(glob.glob(arg)) or [arg] if "*" in arg else [arg])]
            inputs = [a for a in args if a.endswith(".h5") and "-" not in a[:1]]
            if any(not Path(a).exists() for a in inputs if a not in ("model.h5",)):
                continue  # names a file no example here makes (e.g. a folder of uSD logs)
            res = CliRunner().invoke(MAINS[argv[0]], args)
            assert res.exit_code == 0, f"{doc.name}: {' '.join(argv)}\n{res.output}"
            ran += 1
    finally:
        gsim.close_all()
    assert ran >= 1


# --- Python examples -------------------------------------------------------------------------

_PYTHON = ("python", "py")
OLD_PATHS = set(MOVED)  # kept for callers; the docs show the current paths
MADE_BY = {"flight.rrd": ["replay", "flight.h5", "--rrd", "flight.rrd"]}
"""Files a Python example reads besides the scratch folder's, made by a documented command."""


def python_blocks(path: Path) -> list[tuple[int, str]]:
    """``(line, source)`` of every Python code block of ``path``."""
    out, lang, start, body = [], None, 0, []
    for i, line in enumerate(path.read_text().splitlines(), 1):
        m = _FENCE.match(line.strip())
        if m and lang is None:
            lang, start, body = m.group(1), i + 1, []
        elif m:
            if lang in _PYTHON:
                out.append((start, "\n".join(body) + "\n"))
            lang = None
        elif lang is not None:
            body.append(line)
    return out


PY = [(p, line, src) for p in DOCS for line, src in python_blocks(p)]
PY_IDS = [f"{p.name}:{line}" for p, line, _ in PY]


def free_names(source: str) -> set[str]:
    """Names an example uses but neither assigns nor imports (nor are builtins)."""
    tree = ast.parse(source)
    bound = {a.asname or a.name.split(".")[0] for n in ast.walk(tree)
             if isinstance(n, ast.Import | ast.ImportFrom) for a in n.names}
    bound |= {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)
              and isinstance(n.ctx, ast.Store)}
    used = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)
            and isinstance(n.ctx, ast.Load)}
    return used - bound - set(dir(builtins))


def _given() -> dict[str, object]:
    """What the examples take from the text around them: flight data ``u``, ``y`` of a known
    system as ``data`` (``IOData``, dt 0.02 s) and a second flight ``val`` to validate on."""
    import numpy as np

    import sysid
    from tests.sysid.systems import open_loop, random_stable_system

    system = random_stable_system(n_states=4, n_inputs=2, n_outputs=2,
                                  rng=np.random.default_rng(3), dt=0.02)
    data, val = (open_loop(system, n_samples=1500, rng=np.random.default_rng(seed)).data
                 for seed in (1, 2))
    assert isinstance(data, sysid.IOData)
    return {"u": data.u, "y": data.y, "data": data, "val": val}


def test_the_docs_show_python_examples():
    assert {p.name for p, _, _ in PY} >= {"sysid.md", "session-format.md", "viewing.md"}


@pytest.mark.parametrize(("doc", "line", "source"), PY, ids=PY_IDS)
def test_documented_python_imports_exist_at_their_current_path(doc, line, source):
    """Each example compiles and every name it imports exists where it imports it from, at the
    current path (not one of the old paths kept for callers)."""
    tree = ast.parse(source, filename=f"{doc.name}:{line}")
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            modules = [(a.name, None) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            modules = [(node.module, a.name) for a in node.names]
        else:
            continue
        for module, name in modules:
            assert module not in OLD_PATHS, f"{doc.name}:{line}: {module} is an old path"
            mod = importlib.import_module(module)
            if name is not None and not hasattr(mod, name):
                importlib.import_module(f"{module}.{name}")  # a sub-module, or ImportError


@pytest.mark.parametrize(("doc", "line", "source"), PY, ids=PY_IDS)
def test_documented_python_runs(doc, line, source, scratch, tmp_path, monkeypatch):
    """Each example runs as written, in a copy of the scratch folder, with only the names the
    surrounding text defines given (see :func:`_given`)."""
    for f in scratch.rglob("*.h5"):
        target = tmp_path / f.relative_to(scratch)
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(f.read_bytes())
    monkeypatch.chdir(tmp_path)
    for name, argv in MADE_BY.items():
        if name in source:
            res = CliRunner().invoke(gs_main, argv)
            assert res.exit_code == 0 and Path(name).is_file(), res.output
    missing = free_names(source)
    given = _given() if missing else {}
    assert missing <= set(given), f"{doc.name}:{line}: define {sorted(missing - set(given))}"
    namespace = {"__name__": "__doc_example__", **{k: given[k] for k in missing}}
    try:
        exec(compile(source, f"{doc.name}:{line}", "exec"), namespace)
    finally:
        gsim.close_all()
