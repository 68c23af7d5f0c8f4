"""The selection says what the held-out score cannot check: the gain of a mode slower than its
windows (a near-integrating plant). A robustness study's closed loop (poles 0.999 and 0.8 at
2 ms, PI control) chose a model whose DC gain was 7 times the plant's at a held-out score of
82 %, and the true plant itself scored below it: the note is what the user gets there."""

from __future__ import annotations

import dataclasses
import io
import math

import numpy as np
from rich.console import Console

import sysid
from sysid.cli_sweep import print_selection, selection_json, slow_mode_note


def _selection():
    rng = np.random.default_rng(3)
    u = rng.standard_normal((1500, 1))
    plant = sysid.StateSpaceModel(A=[[0.5]], B=[[1.0]], C=[[1.0]], dt=0.01)
    y = plant.simulate(u) + 0.05 * rng.standard_normal((1500, 1))
    return sysid.identify(sysid.IOData(u=u, y=y, dt=0.01), orders=[1], pasts=[5], futures=[5])


def test_a_mode_slower_than_the_scoring_windows_is_said_with_the_band_checked():
    sel = _selection()
    assert sel.window_s is not None and slow_mode_note(sel) == ""  # 0.5: 14 ms, checked
    assert selection_json(sel)["slow_mode_note"] == ""
    slow = dataclasses.replace(sel, model=sel.model.replace(A=np.array([[0.999]])))
    note = slow_mode_note(slow)
    tau = -0.01 / math.log(0.999)
    assert note.startswith(f"slowest mode: time constant {tau:.3g} s, longer than the "
                           f"{sel.window_s:.3g} s scoring windows")
    assert f"above about {1 / sel.window_s:.2g} Hz, not its gain below" in note
    record = selection_json(slow)
    assert record["slowest_time_constant_s"] == tau and record["slow_mode_note"] == note
    on_circle = dataclasses.replace(sel, model=sel.model.replace(A=np.array([[1.0]])))
    assert "slowest mode: an integrator" in slow_mode_note(on_circle)
    assert selection_json(on_circle)["slowest_time_constant_s"] == "inf"


def test_the_note_is_printed_under_the_choice():
    slow = _selection()
    slow = dataclasses.replace(slow, model=slow.model.replace(A=np.array([[0.999]])))
    out = io.StringIO()
    print_selection(Console(file=out, width=300), slow)
    lines = out.getvalue().splitlines()
    chosen = next(i for i, ln in enumerate(lines) if ln.startswith("chosen:"))
    assert any(ln.startswith("slowest mode: time constant") for ln in lines[chosen + 1:])
