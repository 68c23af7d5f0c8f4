"""The package boundaries the architecture promises (docs/architecture.md, "Packages").

Checked on the source (which package imports which, at module level or anywhere) and, for what
flying loads, in a fresh interpreter through ``sys.modules``.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _imports(path: Path, *, module_level_only: bool = False) -> set[str]:
    """Top-level package names ``path`` imports (absolute imports; relative ones stay inside)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    todo: list[ast.AST] = [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
        for child in ast.iter_child_nodes(node):
            if module_level_only and isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef):
                continue  # a lazy import inside a function is allowed where the rules say so
            todo.append(child)
    return names


def _modules(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def _offenders(package: str, forbidden: set[str], *, module_level_only: bool = False) -> list[str]:
    return [f"{p.relative_to(ROOT).as_posix()} imports {sorted(used & forbidden)}"
            for p in _modules(package)
            if (used := _imports(p, module_level_only=module_level_only)) & forbidden]


def test_the_checker_sees_module_level_and_lazy_imports(tmp_path):
    src = tmp_path / "m.py"
    src.write_text("import a.b\nfrom c import d\ntry:\n    import e\nexcept ImportError:\n"
                   "    pass\ndef f():\n    import g\n    from h.i import j\nfrom . import k\n")
    assert _imports(src) == {"a", "c", "e", "g", "h"}
    assert _imports(src, module_level_only=True) == {"a", "c", "e"}


def test_groundstation_never_imports_sysid_at_module_level():
    assert not _offenders("groundstation", {"sysid"}, module_level_only=True)


def test_sysid_never_imports_groundstation():
    assert not _offenders("sysid", {"groundstation"})


@pytest.mark.parametrize("package", ["cfsession", "cfcommon"])
def test_neutral_packages_import_neither_side_nor_cflib(package):
    assert _modules(package), f"{package}/ is missing"
    assert not _offenders(package, {"groundstation", "sysid", "cflib"})


def test_the_session_format_needs_no_rerun_nor_click():
    assert not _offenders("cfsession", {"rerun", "click", "rich"})


def test_sysid_reads_sessions_only_in_session_io_and_talks_to_rerun_only_in_viz():
    offenders = []
    for path in _modules("sysid"):
        used = _imports(path)
        if "cfsession" in used and path.name != "session_io.py":
            offenders.append(f"{path.name} imports cfsession")
        if "rerun" in used and path.name != "viz.py":
            offenders.append(f"{path.name} imports rerun")
    assert not offenders, offenders


def test_one_groundstation_module_talks_to_rerun():
    users = [p.relative_to(ROOT).as_posix() for p in _modules("groundstation")
             if "rerun" in _imports(p)]
    assert users == ["groundstation/live.py"], users


def test_nothing_outside_sim_knows_about_the_simulator():
    """Only the link installs the sim:// driver, as one more link driver among cflib's (and the
    `groundstation sim` command serves simulated vehicles over UDP). The emulated Crazyradio's one
    hook is the USB backend choice (``usb_backend``, used by dongle.py and scan) and the
    ``--emulated-radio`` flags of fly and scan."""
    users = sorted(p.relative_to(ROOT).as_posix() for p in _modules("groundstation")
                   if "sim" not in p.relative_to(ROOT / "groundstation").parts[:1]
                   and "groundstation.sim" in p.read_text(encoding="utf-8"))
    assert users == ["groundstation/commands/fly.py", "groundstation/commands/scan.py",
                     "groundstation/commands/sim.py", "groundstation/dongle.py",
                     "groundstation/flight/link.py"], users


def _loaded_after(*modules: str) -> list[str]:
    """Module names in ``sys.modules`` after importing ``modules`` in a fresh interpreter."""
    code = ("import importlib, json, sys\n"
            f"for m in {list(modules)!r}:\n    importlib.import_module(m)\n"
            "print(json.dumps(sorted(sys.modules)))\n")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         check=True, timeout=120)
    return json.loads(out.stdout)


def test_flying_loads_no_identification_code():
    loaded = _loaded_after("groundstation.flight.runner", "groundstation.recorder",
                           "groundstation.commands.fly", "groundstation.commands.plan")
    assert "groundstation.flight.runner" in loaded  # the check itself ran
    bad = [m for m in loaded if m == "sysid" or m.startswith("sysid.") or m == "scipy.linalg"]
    assert not bad, bad


def test_reading_a_session_loads_neither_side_nor_cflib_nor_rerun():
    loaded = _loaded_after("cfsession")
    assert "cfsession.reader" in loaded and "h5py" in loaded
    bad = [m for m in loaded if m.split(".")[0] in {"groundstation", "sysid", "cflib", "rerun"}]
    assert not bad, bad
