"""Pre-flight checks against the TOC and the per-block packet accounting, with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from groundstation.errors import LinkError
from groundstation.flight import block_summary
from groundstation.flight.blocks import FLIGHT_BLOCKS, LOG_MAX_BYTES, plan_blocks

TOC_2025 = {**{f"motor.m{i}": "uint16_t" for i in range(1, 5)},
            **{f"acc.{a}": "float" for a in "xyz"}, **{f"gyro.{a}": "float" for a in "xyz"}}


def test_types_come_from_the_toc():
    old = {**TOC_2025, **{f"motor.m{i}": "uint32_t" for i in range(1, 5)}}  # pre-2024.10
    for toc, dtype, size in ((TOC_2025, "<u2", 8), (old, "<u4", 16)):
        blocks = plan_blocks(toc_type=toc.get, blocks=FLIGHT_BLOCKS, period_s=0.02)
        motors = blocks[0]
        assert motors.n_bytes == size and [b.n_bytes for b in blocks[1:]] == [12, 12]
        assert [f.dtype for f in motors.spec().fields[2:]] == [dtype] * 4
        assert [f.name for f in motors.spec().fields] == ["host_time", "fw_time_ms",
                                                          "m1", "m2", "m3", "m4"]


def test_missing_variable_is_named():
    toc = {k: v for k, v in TOC_2025.items() if k != "gyro.y"}
    with pytest.raises(LinkError, match=r"^log variable gyro.y \(block gyro\) is not in"):
        plan_blocks(toc_type=toc.get, blocks=FLIGHT_BLOCKS, period_s=0.02)


def test_block_beyond_26_bytes_is_refused_before_flight():
    toc = {**TOC_2025, "stabilizer.roll": "float"}
    six = {"big": ("acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z")}  # 24 bytes: fits
    assert plan_blocks(toc_type=toc.get, blocks=six, period_s=0.02)[0].n_bytes == 24
    seven = {"big": (*six["big"], "stabilizer.roll")}  # 28 bytes
    with pytest.raises(LinkError, match=f"block big needs 28 bytes .* {LOG_MAX_BYTES}"):
        plan_blocks(toc_type=toc.get, blocks=seven, period_s=0.02)


def test_block_summary_counts_gaps_and_unwraps_the_24_bit_tick():
    ms = np.arange(0, 2000, 20)  # 100 packets
    kept = np.delete(ms, [10, 11, 12, 50])  # 4 lost
    assert block_summary(fw_ms=kept, period_s=0.02) == {
        "received": 96, "expected": 100, "dropped": 4, "missing_at_end": 0}
    wrapped = (np.arange(2**24 - 100, 2**24 + 100, 20) % 2**24).tolist()
    assert block_summary(fw_ms=wrapped, period_s=0.02) == {
        "received": 10, "expected": 10, "dropped": 0, "missing_at_end": 0}
    assert block_summary(fw_ms=[], period_s=0.02)["expected"] == 0
    # jitter: a 45 ms step made up for by a 15 ms one is no loss (SITL: "563 / 563, 1 dropped")
    jittered = ms.copy()
    jittered[30:40] += 25
    jittered[40] += 5
    assert block_summary(fw_ms=jittered, period_s=0.02) == {
        "received": 100, "expected": 100, "dropped": 0, "missing_at_end": 0}


def test_block_summary_counts_the_packets_missing_up_to_the_end_of_the_flight():
    ms = np.arange(0, 2000, 20)  # 100 packets, then 1 s of silence before the link closed
    assert block_summary(fw_ms=ms, period_s=0.02, silence_s=1.0) == {
        "received": 100, "expected": 147, "dropped": 47, "missing_at_end": 47}
    # a packet still on its way at the end (less than a period plus the allowance) is not lost
    assert block_summary(fw_ms=ms, period_s=0.02, silence_s=0.06)["dropped"] == 0
    assert block_summary(fw_ms=[5], period_s=0.5, silence_s=2.0)["missing_at_end"] == 3
