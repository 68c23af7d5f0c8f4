"""A session's folder renamed or deleted while the file is open (on POSIX the open file lives
on): ``close`` never names a file that is not there. Moved: the session is where it went, and
``close`` returns that name. Deleted: it is written again from the open file to its name, or
to the nearest folder that takes it when its own cannot be made again. The summary stored in
the file names the file, never a folder that may have moved."""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

import cfsession.saving as saving
from cfsession import SessionError, SessionWriter, open_session
from cfsession.schema import log_block_spec
from cfsession.writer import standard_streams

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="open files outlive their name")

GYRO = log_block_spec(name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"],
                      period_s=0.02)


def _writer(folder):
    w = SessionWriter(folder / "s.h5", streams=[GYRO, *standard_streams()], flush_interval=0.0)
    w.extend("gyro", [(k * 0.02, 20 * k, 0.1, 0.2, float(k)) for k in range(300)])
    return w


def _finish(w: SessionWriter) -> None:
    w.extend("gyro", [(k * 0.02, 20 * k, 0.1, 0.2, float(k)) for k in range(300, 400)])


def _whole(path) -> None:
    s = open_session(path)
    assert s.closed_cleanly and not s.problems
    np.testing.assert_array_equal(s["gyro"].data["z"], np.arange(400))


def test_a_renamed_folder_moves_the_session(tmp_path):
    out = tmp_path / "out"
    w = _writer(out)
    out.rename(tmp_path / "moved")
    _finish(w)
    path = w.close()
    assert path == tmp_path / "moved" / "s.h5" == w.path
    assert not out.exists()
    assert w.notes == [f"{out / 's.h5'} was moved while being written; the session is now "
                       f"{path}"]
    _whole(path)


def test_a_deleted_folder_is_made_again_and_the_session_written_to_it(tmp_path):
    out = tmp_path / "out"
    w = _writer(out)
    shutil.rmtree(out)
    _finish(w)
    assert w.close() == out / "s.h5"
    assert len(w.notes) == 1 and "was deleted while being written" in w.notes[0]
    assert "written again, from the still open file" in w.notes[0]
    _whole(out / "s.h5")
    assert [p.name for p in out.iterdir()] == ["s.h5"]


def test_a_deleted_file_whose_name_was_taken_is_written_to_the_next_name(tmp_path):
    w = _writer(tmp_path)
    (tmp_path / "s.h5").unlink()
    (tmp_path / "s.h5").write_bytes(b"another file")
    _finish(w)
    assert w.close() == tmp_path / "s-2.h5"
    assert (tmp_path / "s.h5").read_bytes() == b"another file"
    _whole(tmp_path / "s-2.h5")


def test_a_deleted_folder_whose_name_was_taken_puts_the_session_in_the_folder_above(tmp_path):
    out = tmp_path / "out"
    w = _writer(out)
    shutil.rmtree(out)
    out.write_text("a file now")
    _finish(w)
    assert w.close() == tmp_path / "s.h5" == w.path
    assert w.notes == [f"{out / 's.h5'} was deleted while being written (its folder removed?), "
                       "and writing it again there failed (File exists); the session was "
                       f"written, from the still open file, to {tmp_path / 's.h5'} instead"]
    assert out.read_text() == "a file now"
    _whole(tmp_path / "s.h5")


def test_a_session_no_folder_takes_is_one_line(tmp_path, monkeypatch):
    monkeypatch.setattr(saving, "fallbacks", lambda original: [])
    out = tmp_path / "out"
    w = _writer(out)
    shutil.rmtree(out)
    out.write_text("a file now")
    with pytest.raises(SessionError, match="the session is lost") as err:
        w.close()
    assert str(out / "s.h5") in str(err.value) and "\n" not in str(err.value)
    assert out.read_text() == "a file now"


def test_the_folders_tried_are_the_nearest_above_then_here_then_the_temporary_one(
        tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path / "..")
    tried = saving.fallbacks(tmp_path / "a" / "b" / "s.h5")
    assert tried[:2] == [tmp_path, tmp_path.parent]
    assert tried[2:] == [] or tried[2:] == [Path(tempfile.gettempdir())]


def test_the_stored_summary_names_the_file_not_a_folder_that_may_move(tmp_path):
    out = tmp_path / "out"
    w = _writer(out)
    out.rename(tmp_path / "moved")
    w.close(summary={"file": str(out / "s.h5"), "plan": "p"})
    s = open_session(tmp_path / "moved" / "s.h5")
    assert s.json_meta("summary") == {"file": "s.h5", "plan": "p"}


def test_a_session_written_again_under_another_name_stores_that_name(tmp_path):
    w = _writer(tmp_path)
    (tmp_path / "s.h5").unlink()
    (tmp_path / "s.h5").write_bytes(b"another file")
    assert w.close(summary={"file": str(tmp_path / "s.h5")}) == tmp_path / "s-2.h5"
    assert open_session(tmp_path / "s-2.h5").json_meta("summary") == {"file": "s-2.h5"}


def test_a_deleted_current_folder_is_no_reason_to_lose_the_session(tmp_path, monkeypatch):
    """Flying from inside the sessions folder (``cd sessions; fly ... --out /abs/sessions``),
    the folder deleted: the current folder is gone, and the session is written again to its
    own folder all the same (the fall-backs are only looked for after that fails)."""
    out = tmp_path / "out"
    w = _writer(out)
    monkeypatch.chdir(out)  # restored after the test
    shutil.rmtree(out)
    _finish(w)
    assert w.close() == out / "s.h5"
    assert len(w.notes) == 1 and "written again, from the still open file" in w.notes[0]
    _whole(out / "s.h5")


def test_a_deleted_current_folder_and_a_taken_folder_name_go_to_the_folder_above(
        tmp_path, monkeypatch):
    out = tmp_path / "out"
    w = _writer(out)
    monkeypatch.chdir(out)
    shutil.rmtree(out)
    out.write_text("a file now")
    _finish(w)
    assert w.close() == tmp_path / "s.h5"
    assert saving.fallbacks(out / "s.h5") == [tmp_path, Path(tempfile.gettempdir())]
    assert "instead" in w.notes[0]
    _whole(tmp_path / "s.h5")


def test_the_file_system_root_is_never_a_folder_tried(tmp_path, monkeypatch):
    monkeypatch.setattr(saving.os, "access", lambda path, mode: True)  # as root
    monkeypatch.chdir(tmp_path)
    assert saving.fallbacks(Path("/sessions/x.h5")) == [tmp_path, Path(tempfile.gettempdir())]
    monkeypatch.chdir("/")
    assert saving.fallbacks(Path("/sessions/x.h5")) == [Path(tempfile.gettempdir())]


def test_only_the_nearest_existing_folder_above_is_tried_and_only_if_writable(
        tmp_path, monkeypatch):
    locked = tmp_path / "locked"
    locked.mkdir()
    monkeypatch.setattr(saving.os, "access",
                        lambda path, mode: not saving._same(path, locked))
    monkeypatch.chdir(tmp_path / "..")
    tried = saving.fallbacks(locked / "gone" / "s.h5")
    assert locked not in tried and tmp_path not in tried  # never further up than the nearest
    assert tried == [tmp_path.parent, Path(tempfile.gettempdir())]
