"""The package boundaries the architecture promises, checked on the source."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_sysid_imports_groundstation_only_in_session_io_and_rerun_only_in_viz():
    offenders = []
    for path in sorted((ROOT / "sysid").glob("*.py")):
        used = _imports(path)
        if "groundstation" in used and path.name != "session_io.py":
            offenders.append(f"{path.name} imports groundstation")
        if "rerun" in used and path.name != "viz.py":
            offenders.append(f"{path.name} imports rerun")
    assert not offenders, offenders


def test_one_groundstation_module_talks_to_rerun():
    users = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "groundstation").rglob("*.py")
                   if "rerun" in _imports(p))
    assert users == ["groundstation/live.py"], users


def test_nothing_outside_sim_knows_about_the_simulator():
    """Only link.py installs the sim:// driver, as one more link driver among cflib's (and the
    `groundstation sim` command serves simulated vehicles over UDP)."""
    users = sorted(p.relative_to(ROOT).as_posix() for p in (ROOT / "groundstation").rglob("*.py")
                   if "sim" not in p.relative_to(ROOT / "groundstation").parts[:1]
                   and "groundstation.sim" in p.read_text(encoding="utf-8"))
    assert users == ["groundstation/commands/sim.py", "groundstation/link.py"], users
