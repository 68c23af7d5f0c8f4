"""A writer killed with SIGKILL leaves a readable file holding all but the last second."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from cfsession import open_session

CHILD = textwrap.dedent(
    """
    import sys, time
    from cfsession.writer import SessionWriter, standard_streams
    from cfsession.schema import log_block_spec
    gyro = log_block_spec(name="gyro", variables=[("gyro.x", "float"), ("gyro.y", "float"),
                                                  ("gyro.z", "float")], period_s=0.02)
    w = SessionWriter(sys.argv[1], streams=[gyro, *standard_streams()],
                      metadata={"uri": "test://"})
    w.phase(t=0.0, phase_id=0, name="excite", kind="excitation")
    k = 0
    t0 = time.time()
    while True:
        now = time.time()
        # host_time: wall seconds since t0; y: sequence number (to find holes)
        w.append("gyro", (now - t0, (20 * k) % (1 << 24), 0.0, float(k), 0.0))
        if k % 5 == 0:
            w.append("setpoints", (now - t0, 0.0, 0.0, 0.0, 30000, 0, k // 5))
        if k == 100:
            print("running", repr(t0), flush=True)
        k += 1
        time.sleep(0.004)
    """
)


@pytest.mark.skipif(sys.platform == "win32", reason="SIGKILL")
def test_sigkill_loses_at_most_the_last_second(tmp_path):
    path = tmp_path / "killed.h5"
    script = tmp_path / "writer.py"
    script.write_text(CHILD)
    proc = subprocess.Popen(
        [sys.executable, str(script), str(path)], stdout=subprocess.PIPE, text=True
    )
    try:
        word, t0 = proc.stdout.readline().split()
        assert word == "running"
        time.sleep(2.7)
    finally:
        killed_at = time.time()
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
    s = open_session(path)
    assert not s.closed_cleanly
    assert any("did not close" in p for p in s.problems)
    gyro = s["gyro"]
    seq = gyro.data["y"]
    assert len(seq) > 100
    np.testing.assert_array_equal(seq, np.arange(len(seq)))  # no holes, no partial rows
    newest = float(t0) + float(np.max(gyro.time))  # wall time of the last row in the file
    # Everything appended more than ~1 s before the kill is in the file (0.3 s slack for
    # scheduling on a loaded 2-core machine).
    assert killed_at - newest < 1.0 + 0.3
    assert len(s["setpoints"]) >= len(seq) // 5 - 1
    assert [p.name for p in s.phases()] == ["excite"]
