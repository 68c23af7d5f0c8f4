"""cfsession/schema.py: log-block field names, types and units; the fixed streams' rows."""
from __future__ import annotations

import numpy as np
import pytest

from cfsession.schema import (
    events_spec,
    link_spec,
    log_block_spec,
    phases_spec,
    setpoints_spec,
    unit_of,
)


def test_log_block_fields_types_units_and_sources():
    spec = log_block_spec(name="imu", period_s=0.01,
                          variables=[("gyro.x", "float"), ("motor.m1", "uint16_t"),
                                     ("stabilizer.roll", "float"), ("controller.roll", "FP16")])
    assert spec.kind == "log" and spec.period_s == 0.01
    names = [f.name for f in spec.fields]
    # 'roll' appears twice: both get their full name, the unique ones their short name
    assert names == ["host_time", "fw_time_ms", "x", "m1", "stabilizer_roll", "controller_roll"]
    assert spec.dtype["fw_time_ms"] == np.dtype("<u4") and spec.dtype["m1"] == np.dtype("<u2")
    assert spec.dtype["controller_roll"] == np.dtype("<f4")  # FP16 is stored widened
    assert [f.unit for f in spec.fields[2:]] == ["deg/s", "PWM (0-65535)", "deg", "deg"]
    assert [f.source for f in spec.fields[2:]] == ["gyro.x", "motor.m1", "stabilizer.roll",
                                                   "controller.roll"]
    assert spec.attrs["cflib_types"] == "float,uint16_t,float,FP16"


def test_unknown_cflib_type_is_refused():
    with pytest.raises(ValueError, match=r"log variable gyro\.x: unknown type 'float128'"):
        log_block_spec(name="b", period_s=0.01, variables=[("gyro.x", "float128")])


def test_units_by_name_then_group():
    assert unit_of("pm.vbat") == "V" and unit_of("acc.z") == "g" and unit_of("foo.bar") == ""


@pytest.mark.parametrize("spec", [setpoints_spec(), events_spec(), phases_spec(), link_spec()])
def test_every_stream_starts_with_host_time_and_fills_with_nan(spec):
    assert spec.fields[0].name == "host_time" and spec.fields[0].unit == "s"
    row = spec.fill_row()
    assert row.dtype == spec.dtype and np.isnan(row["host_time"])
