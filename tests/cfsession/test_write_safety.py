"""Writing never follows a planted symlink, and a fast flight is flushed by flight time (#13)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from cfsession import SessionError, SessionWriter, open_session
from cfsession.schema import log_block_spec
from cfsession.writer import standard_streams
from groundstation.recorder import Recorder

GYRO = log_block_spec(name="gyro", variables=[(f"gyro.{a}", "float") for a in "xyz"],
                      period_s=0.02)


def _rows(t0: float, n: int) -> list[tuple]:
    return [(t0 + 0.02 * k, 1000 + 20 * k, 0.1, 0.2, 0.3) for k in range(n)]


def test_the_clean_close_rewrite_does_not_follow_a_planted_symlink(tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious")
    out = tmp_path / "s.h5"
    # the old, predictable name of the repack file
    os.symlink(victim, tmp_path / "s.h5.repack")
    with SessionWriter(out, streams=[GYRO, *standard_streams()]) as w:
        w.extend("gyro", _rows(0.0, 50))
    assert victim.read_text() == "precious"
    assert len(open_session(out)["gyro"]) == 50
    assert [p.name for p in tmp_path.iterdir() if p.name.endswith(".repack")] == ["s.h5.repack"]


def test_a_symlink_at_the_session_path_is_refused(tmp_path):
    target = tmp_path / "elsewhere.h5"
    link = tmp_path / "s.h5"
    os.symlink(target, link)  # dangling: exists() is False, a plain open would create target
    with pytest.raises(SessionError, match="symbolic link"):
        SessionWriter(link, streams=[GYRO, *standard_streams()])
    assert not target.exists()


def test_the_recorder_flushes_within_the_first_second_of_flight_time(tmp_path):
    """At 20x a whole hover fits in one wall second: rows must reach the file by flight time,
    not only after a wall-clock second (the writer's own interval is made huge here)."""
    rec = Recorder(tmp_path / "fast.h5", flush_interval=1.0)
    rec.begin(streams=[GYRO, *standard_streams()], metadata={})
    rec._writer.flush_interval = 3600.0  # no wall-clock flush during this test
    rec.rows("gyro", _rows(0.0, 40))    # 0.00 .. 0.78 s of flight
    assert len(open_session(rec.path)["gyro"]) == 0
    rec.rows("gyro", _rows(0.8, 20))    # .. 1.18 s: past the first second
    assert len(open_session(rec.path)["gyro"]) == 60
    rec.end(summary={"duration_s": 1.2})


def test_a_summary_longer_than_its_attribute_is_still_json(tmp_path):
    """The summary attribute holds 4096 characters; a longer summary (a disk-full cause naming
    a long --out path, many file notes) was cut there, its JSON broken, and ``info`` showed no
    summary at all (safety review). Long texts are shortened, then the largest entries left
    out and named."""
    from cfsession.writer import SUMMARY_CHARS, summary_json

    long_path = "/data/" + "x" * 6000 + "/flight.h5"
    rec = Recorder(tmp_path / "long.h5")
    rec.begin(streams=[GYRO, *standard_streams()], metadata={})
    rec.rows("gyro", _rows(0.0, 5))
    rec.end(summary={"aborted": True, "cause": f"disk full: {long_path}", "duration_s": 1.5,
                     "file_notes": [f"saved to {long_path}"] * 3})
    summary = open_session(rec.path).json_meta("summary")
    assert summary["aborted"] is True and summary["duration_s"] == 1.5
    assert summary["cause"].startswith("disk full: /data/xxx") and summary["cause"].endswith("...")
    # entries too big even shortened are left out, and named
    many = {"blocks": {f"b{i}": {"note": "y" * 100} for i in range(200)}, "duration_s": 2.0}
    text = summary_json(many)
    assert len(text) <= SUMMARY_CHARS
    assert json.loads(text) == {"duration_s": 2.0, "truncated": "1 entries left out"}
    # many entries, long names: the outcome is kept, and the JSON is strict (review)
    crowd = {**{f"k{i}" * 20: i for i in range(1000)}, "aborted": np.True_, "cause": "x" * 9000,
             "jitter_ms": float("nan"), "n": np.int64(3)}
    kept = json.loads(summary_json(crowd), parse_constant=lambda c: pytest.fail(c))
    assert kept["aborted"] is True and kept["cause"].startswith("xxx") and kept["n"] == 3
    assert kept["jitter_ms"] is None and len(summary_json(crowd)) <= SUMMARY_CHARS
