"""The package boundaries the architecture promises, read from their one statement: the table
"Packages and what each may import" of docs/architecture.md.

Checked on the source (every absolute import of every module, at module level or inside a
function, against the rows of its package and of itself) and, for what flying and reading a
session load, in a fresh interpreter through ``sys.modules``. A separate test pins the promises
of issue 12 in the table itself, so the rules cannot be relaxed by editing the table alone.
"""

from __future__ import annotations

import ast
import fnmatch
import json
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
TABLE_DOC = ROOT / "docs" / "architecture.md"
TABLE_HEADING = "## Packages and what each may import"
TOP_PACKAGES = ("cfsession", "cfcommon", "groundstation", "sysid", "bench")
_NAME = re.compile(r"`([A-Za-z_][\w.]*\*?)`")


@dataclass(frozen=True)
class Row:
    """One line of the table: the packages (or single modules) it is about and what they may
    import at module level, what only inside a function, and what never."""

    names: tuple[str, ...]
    may: frozenset[str]
    lazily: frozenset[str]
    never: frozenset[str]


def read_table(path: Path = TABLE_DOC) -> dict[str, Row]:
    """The rows of the table under :data:`TABLE_HEADING`, by package or module name.

    Columns: package | holds | may import | only inside a function | never; names are the
    backticked words of a cell (the "holds" column is prose). A module name may end in ``*``:
    ``sysid.cli*`` is every module of ``sysid`` whose name starts with ``cli``."""
    lines = path.read_text(encoding="utf-8").splitlines()
    start = lines.index(TABLE_HEADING)
    rows: dict[str, Row] = {}
    for line in lines[start + 1:]:
        if line.startswith("#"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if not line.startswith("|") or len(cells) != 5 or set(cells[0]) <= {"-", " ", ":"}:
            continue
        names = tuple(_NAME.findall(cells[0]))
        if not names:  # the header
            continue
        row = Row(names=names, may=frozenset(_NAME.findall(cells[2])),
                  lazily=frozenset(_NAME.findall(cells[3])),
                  never=frozenset(_NAME.findall(cells[4])))
        for name in names:
            assert name not in rows, f"{name} has two rows in {path.name}"
            rows[name] = row
    return rows


TABLE = read_table()


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _is_repo_module(name: str) -> bool:
    base = ROOT.joinpath(*name.split("."))
    return base.with_suffix(".py").is_file() or (base / "__init__.py").is_file()


def imports(path: Path) -> set[tuple[str, bool]]:
    """``(module, lazy)`` for every absolute import of ``path``; ``lazy`` when it sits inside a
    function. ``from a import b`` names ``a.b`` when ``b`` is a module of this repository.
    Relative imports stay inside their package (the project uses none)."""
    found: set[tuple[str, bool]] = set()

    def walk(node: ast.AST, lazy: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = lazy or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            if isinstance(child, ast.Import):
                found.update((a.name, inner) for a in child.names)
            elif isinstance(child, ast.ImportFrom) and child.module and child.level == 0:
                for a in child.names:
                    sub = f"{child.module}.{a.name}"
                    found.add((sub if _is_repo_module(sub) else child.module, inner))
            walk(child, inner)

    walk(ast.parse(path.read_text(encoding="utf-8")), False)
    return found


def _covers(entries: frozenset[str] | set[str], module: str) -> bool:
    return any(module == e or module.startswith(e + ".") for e in entries)


def _package_of(module: str) -> str | None:
    """The most specific package row a module belongs to (module rows only add to it)."""
    parts = module.split(".")
    for k in range(len(parts), 0, -1):
        name = ".".join(parts[:k])
        if name in TABLE and (ROOT.joinpath(*parts[:k]) / "__init__.py").is_file():
            return name
    return None


def violations(path: Path) -> list[str]:
    """What ``path`` imports that the rows of its package and of itself do not allow."""
    me = _module_name(path)
    package = _package_of(me)
    if package is None:
        return [f"{me}: no row of the table covers it"]
    rows = [TABLE[package]] + [row for name, row in TABLE.items()
                               if name != package and fnmatch.fnmatchcase(me, name)]
    may = set().union(*(r.may for r in rows))
    lazily = may.union(*(r.lazily for r in rows))
    bad = []
    for target, lazy in sorted(imports(path)):
        if target.split(".")[0] in sys.stdlib_module_names:
            continue
        if _is_repo_module(target) and _package_of(target) == package:
            continue  # inside its own package
        if not _covers(lazily if lazy else may, target):
            where = "inside a function" if lazy else "at module level"
            bad.append(f"{path.relative_to(ROOT).as_posix()} imports {target} {where}")
    return bad


def _packages() -> list[str]:
    return sorted(_module_name(p.parent / "__init__.py") for top in TOP_PACKAGES
                  for p in (ROOT / top).rglob("__init__.py"))


def _sources(top: str) -> list[Path]:
    return sorted((ROOT / top).rglob("*.py"))


def test_the_checker_sees_module_level_and_lazy_imports(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("import a.b\nfrom c import d\ntry:\n    import e\nexcept ImportError:\n"
                   "    pass\ndef f():\n    import g\n    from h.i import j\nfrom . import k\n"
                   "from groundstation import plan\nclass C:\n    def m(self):\n"
                   "        from sysid import iem\n")
    assert imports(src) == {("a.b", False), ("c", False), ("e", False), ("g", True),
                            ("h.i", True), ("groundstation.plan", False), ("sysid.iem", True)}


def test_the_table_has_a_row_for_every_package_and_only_for_real_modules():
    packages = _packages()
    assert {"cfsession", "groundstation.plan", "groundstation.flight", "sysid"} <= set(packages)
    assert sorted(n for n in TABLE if n in packages) == packages
    modules = [_module_name(p) for top in TOP_PACKAGES for p in _sources(top)]
    for name in TABLE:
        assert fnmatch.filter(modules, name), f"{name}: no such module"
    for name, row in TABLE.items():
        assert not (row.may | row.lazily) & row.never, f"{name}: allowed and never"


def test_the_table_keeps_the_promises_of_the_architecture():
    """Issue 12: the session package imports neither side, and neither do the shared helpers;
    flying never imports identification at module level; identification never imports the
    flying side (the old path sysid.excitation only lazily), reads sessions in one module and
    talks to Rerun in one."""
    sides = {"groundstation", "sysid", "cflib"}
    assert TABLE["cfsession"].may | TABLE["cfsession"].lazily <= {"numpy", "h5py"}
    assert {"cfcommon", "rerun", "click"} | sides <= TABLE["cfsession"].never
    assert sides | {"cfsession"} <= TABLE["cfcommon"].never
    for name, row in TABLE.items():
        if name.startswith("groundstation"):
            assert not _covers(row.may, "sysid"), name
            lazily_sysid = _covers(row.lazily, "sysid")
            assert not lazily_sysid or name == "groundstation.commands", name
        if name.startswith("sysid"):
            assert not _covers(row.may, "groundstation"), name
            assert not _covers(row.may | row.lazily, "cflib"), name
            if _covers(row.lazily, "groundstation"):
                assert (name, row.lazily) == ("sysid.excitation",
                                             {"groundstation.plan.excitation"}), name
            if _covers(row.may, "cfsession"):
                assert name == "sysid.session_io", name
            if _covers(row.lazily, "cfsession"):  # model files opened through the guard
                assert (name, row.lazily) == ("sysid.model_io",
                                             {"cfsession.guard", "cfsession.errors"}), name
            if _covers(row.may | row.lazily, "rerun"):
                assert name == "sysid.viz", name
    rerun_users = {n for n, r in TABLE.items() if n.startswith("groundstation")
                   and _covers(r.may | r.lazily, "rerun")}
    assert rerun_users and all(n.startswith("groundstation.live") for n in rerun_users), \
        rerun_users  # the flight's one Rerun listener


@pytest.mark.parametrize("top", TOP_PACKAGES)
def test_every_import_is_allowed_by_the_table(top):
    assert _sources(top), f"{top}/ is missing"
    bad = [v for path in _sources(top) for v in violations(path)]
    assert not bad, "\n".join(bad)


def test_a_forbidden_import_is_reported(tmp_path, monkeypatch):
    """The checker can fail: a plan module importing the flight runner, or sysid importing
    groundstation at module level, is named."""
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    for pkg in ("groundstation", "groundstation/plan", "groundstation/flight", "sysid"):
        (tmp_path / pkg).mkdir(parents=True, exist_ok=True)
        (tmp_path / pkg / "__init__.py").write_text("")
    (tmp_path / "groundstation/flight/runner.py").write_text("")
    (tmp_path / "groundstation/plan/excitation.py").write_text("")
    plan = tmp_path / "groundstation/plan/bad.py"
    plan.write_text("import numpy\nfrom groundstation.flight import runner\n")
    assert violations(plan) == ["groundstation/plan/bad.py imports groundstation.flight.runner "
                                "at module level"]
    shim = tmp_path / "sysid/excitation.py"
    shim.write_text("from groundstation.plan import excitation\n")
    assert violations(shim) == ["sysid/excitation.py imports groundstation.plan.excitation at "
                                "module level"]


def test_nothing_outside_sim_knows_about_the_simulator():
    """Only the flight's driver list installs the sim:// driver, as one more link driver among
    cflib's (and the `groundstation sim` command serves simulated vehicles over UDP). The
    emulated Crazyradio's one hook is the USB backend choice (``usb_backend``, used by dongle.py
    and scan) and the ``--emulated-radio`` flags of fly and scan."""
    users = sorted(p.relative_to(ROOT).as_posix() for p in _sources("groundstation")
                   if "sim" not in p.relative_to(ROOT / "groundstation").parts[:1]
                   and "groundstation.sim" in p.read_text(encoding="utf-8"))
    assert users == ["groundstation/commands/fly.py", "groundstation/commands/scan.py",
                     "groundstation/commands/sim.py", "groundstation/dongle.py",
                     "groundstation/flight/drivers.py"], users


def _loaded_after(*modules: str) -> list[str]:
    """Module names in ``sys.modules`` after importing ``modules`` in a fresh interpreter."""
    code = ("import importlib, json, sys\n"
            f"for m in {list(modules)!r}:\n    importlib.import_module(m)\n"
            "print(json.dumps(sorted(sys.modules)))\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         check=True, timeout=120)
    return json.loads(out.stdout)


def _under(loaded: list[str], tops: set[str]) -> list[str]:
    return [m for m in loaded if m.split(".")[0] in tops]


def test_flying_loads_no_identification_code():
    loaded = _loaded_after("groundstation.flight.runner", "groundstation.recorder",
                           "groundstation.commands.fly", "groundstation.commands.plan")
    assert "groundstation.flight.runner" in loaded  # the check itself ran
    bad = _under(loaded, {"sysid"}) + [m for m in loaded if m == "scipy.linalg"]
    assert not bad, bad


def test_identification_loads_no_flying_code():
    """``import sysid`` and every module of it, the old paths included, load no groundstation
    and no cflib (sysid.excitation reaches the plan package only when a name is used)."""
    modules = [_module_name(p) for p in _sources("sysid")]
    loaded = _loaded_after(*modules)
    assert "sysid.excitation" in loaded and "sysid.cli" in loaded
    assert not _under(loaded, {"groundstation", "cflib"}), _under(loaded, {"groundstation"})


def test_reading_a_session_loads_neither_side_nor_cflib_nor_rerun():
    loaded = _loaded_after("cfsession")
    assert "cfsession.reader" in loaded and "h5py" in loaded
    bad = _under(loaded, {"groundstation", "sysid", "cflib", "rerun"})
    assert not bad, bad
