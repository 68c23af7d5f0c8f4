"""``make sitl`` (tools/build_sitl.sh): a second call costs nothing; missing tools and a missing
snapshot are one line each, naming what to install or set. (The build itself runs in ``make
test``, before the suite.)"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "tools" / "build_sitl.sh"


def _run(tmp_path: Path, *, path: str, src: Path | None = None) -> subprocess.CompletedProcess:
    env = {**os.environ, "PATH": path, "SITL_OUT": str(tmp_path / "out"),
           "SITL_SRC": str(src or tmp_path / "no-snapshot")}
    return subprocess.run(["/bin/sh", str(SCRIPT)], env=env, capture_output=True, text=True,
                          timeout=60, cwd=tmp_path)


def _bin_without(tmp_path: Path, *missing: str) -> str:
    """A PATH with the usual tools except ``missing``."""
    d = tmp_path / "bin"
    d.mkdir()
    for tool in ("gcc", "cmake", "make", "git", "patch", "tar", "xz", "python3", "cp", "mv",
                 "rm", "mkdir", "ln", "dirname", "cat"):
        where = shutil.which(tool)
        if where and tool not in missing:
            (d / tool).symlink_to(where)
    return str(d)


def test_missing_cmake_names_the_package(tmp_path):
    r = _run(tmp_path, path=_bin_without(tmp_path, "cmake"))
    assert r.returncode == 2
    assert r.stderr.strip().splitlines() == [
        "make sitl: 'cmake' not found; install it: sudo apt-get install cmake"]
    assert not (tmp_path / "out" / "cf2").exists()


def test_missing_snapshot_is_one_line(tmp_path):
    r = _run(tmp_path, path=os.environ["PATH"])
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "no firmware snapshot at" in r.stderr and "SITL_SRC" in r.stderr


def test_second_call_costs_nothing(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    (out / "cf2").write_text("#!/bin/sh\n")
    (out / "cf2").chmod(0o755)
    r = _run(tmp_path, path=_bin_without(tmp_path, "gcc", "cmake"))  # would fail if it built
    assert (r.returncode, r.stdout, r.stderr) == (0, "", "")
