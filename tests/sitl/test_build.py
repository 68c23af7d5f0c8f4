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


def _run(tmp_path: Path, *args: str, path: str, src: Path | None = None
         ) -> subprocess.CompletedProcess:
    env = {**os.environ, "PATH": path, "SITL_OUT": str(tmp_path / "out"),
           "SITL_SRC": str(src or tmp_path / "no-snapshot")}
    return subprocess.run(["/bin/sh", str(SCRIPT), *args], env=env, capture_output=True,
                          text=True, timeout=60, cwd=tmp_path)


def _bin_without(tmp_path: Path, *missing: str) -> str:
    """A PATH with the usual tools except ``missing``."""
    d = tmp_path / "bin"
    d.mkdir()
    for tool in ("gcc", "cmake", "make", "git", "patch", "tar", "xz", "python3", "cp", "mv",
                 "rm", "mkdir", "ln", "dirname", "cat", "stat", "cksum"):
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


def _built(tmp_path: Path, *, key: str) -> None:
    """A stand-in firmware in ``out/`` as a build leaves it, with its cache key."""
    out = tmp_path / "out"
    out.mkdir()
    (out / "cf2").write_text("#!/bin/sh\n")
    (out / "cf2").chmod(0o755)
    (out / "cf2.key").write_text(key)


def test_second_call_costs_nothing(tmp_path):
    key = _run(tmp_path, "--key", path=os.environ["PATH"]).stdout
    _built(tmp_path, key=key)
    r = _run(tmp_path, path=_bin_without(tmp_path, "gcc", "cmake"))  # would fail if it built
    assert (r.returncode, r.stdout, r.stderr) == (0, "", "")


def test_a_changed_snapshot_or_patch_rebuilds(tmp_path):
    _built(tmp_path, key="built from another snapshot or patch\n")
    r = _run(tmp_path, path=_bin_without(tmp_path, "gcc"))  # it tries to build: gcc is needed
    assert r.returncode == 2 and "'gcc' not found" in r.stderr
