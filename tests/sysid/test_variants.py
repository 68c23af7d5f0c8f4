"""Presets of IEM, the offset warning, and method spellings."""

from __future__ import annotations

import logging

import numpy as np

import sysid
from sysid import IOData

from .systems import closed_loop, pbsid_example1

KW = {"order": 4, "past": 10, "future": 10}


def _data(seed: int = 0) -> IOData:
    return closed_loop(pbsid_example1(), n_samples=3000, rng=np.random.default_rng(seed),
                       gain=0.25).data


def test_thesis_variant_is_table_4_3_and_never_a_hybrid():
    data = _data()
    thesis = sysid.iem(data, variant="thesis", **KW)
    explicit = sysid.iem(data, bk_method="thesis", weighting="none", refine=False, **KW)
    np.testing.assert_allclose(thesis.A, explicit.A)
    np.testing.assert_allclose(thesis.B, explicit.B)
    assert thesis.provenance["refine"].startswith("off")
    # asking only for the thesis' B/D no longer gets the predictor refinement on top
    assert sysid.iem(data, bk_method="thesis", **KW).provenance["refine"].startswith("off")
    default = sysid.iem(data, **KW)
    assert default.provenance["refine"] == "off"  # the refinement is opt-in (issue 10)
    assert default.provenance["variant"] == "consistent"
    assert sysid.iem(data, refine=True, **KW).provenance["refine"] == "done"


def test_offsets_are_warned_about_naming_the_channel(caplog):
    data = _data()
    shifted = IOData(u=data.u + 40000.0, y=data.y, dt=data.dt,
                     input_names=["m1", "m2"], output_names=data.output_names)
    with caplog.at_level(logging.WARNING, logger="sysid"):
        sysid.iem(shifted, **KW)
    assert "m1 (mean 4e+04" in caplog.text and "detrend" in caplog.text
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="sysid"):
        sysid.iem(data, **KW)
    assert "far from zero mean" not in caplog.text


def test_po_moesp_is_spelled_either_way():
    data = _data()
    a = sysid.singular_values(data, past=10, future=10, method="po_moesp")
    b = sysid.singular_values(data, past=10, future=10, method="po-moesp")
    np.testing.assert_array_equal(a, b)
