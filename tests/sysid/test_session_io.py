"""load_session against the truth written by tests/sysid/flights.py."""

from __future__ import annotations

import numpy as np
import pytest

from cfsession import SessionWriter, open_session, standard_streams
from cfsession.schema import log_block_spec
from groundstation.errors import SessionError
from sysid.errors import DataError, ParameterError
from sysid.session_io import clock_offset, load_session, load_sessions
from tests.sysid.flights import FW0_MS, HOST_OFFSET, held, known_system, write_flight

# The excitation phase starts at host 5.0 s; the median latency is ~4 ms, so the grid starts at
# firmware 4.496 s after the first tick: just after sample 224 of every stream (offset+jitter
# <= 9 ms), and every grid instant j holds sample 224 + j (or the last one before a drop).
K0, N_EXC = 224, 2000


@pytest.fixture(scope="module")
def flight(tmp_path_factory):
    return write_flight(tmp_path_factory.mktemp("s") / "f.h5", system=known_system(), seed=1)


def test_zoh_values_are_the_logged_samples_on_the_grid(flight) -> None:
    d = load_session(flight.path, detrend=None)
    assert d.n_samples == N_EXC and d.dt == 0.02
    idx = K0 + np.arange(N_EXC)
    expect_u = held(flight.values["motors"], flight.dropped["motors"], idx)
    expect_y = np.hstack([held(flight.values[s], flight.dropped[s], idx) for s in ("acc", "gyro")])
    np.testing.assert_array_equal(d.u, expect_u)
    np.testing.assert_array_equal(d.y, expect_y)
    # a dropped packet really is held, not interpolated or skipped
    k = int(flight.dropped["gyro"][0])
    if K0 < k < K0 + N_EXC:
        assert np.array_equal(d.y[k - K0, 3:], flight.values["gyro"][k - 1])


def test_names_units_source_and_detrend(flight) -> None:
    d = load_session(flight.path)
    assert d.input_names == ("motor.m1", "motor.m2", "motor.m3", "motor.m4")
    assert d.output_names == ("acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z")
    assert d.input_units == ("PWM (0-65535)",) * 4
    assert d.output_units == ("g",) * 3 + ("deg/s",) * 3
    assert d.source == str(flight.path)
    np.testing.assert_allclose(d.u.mean(axis=0), 0, atol=1e-9)
    raw = load_session(flight.path, detrend=None)
    np.testing.assert_allclose(d.y + raw.y.mean(axis=0), raw.y, atol=1e-9)


def test_clock_offset_is_the_median_host_minus_firmware(flight) -> None:
    s = open_session(flight.path)
    fw0 = FW0_MS / 1000.0
    off = clock_offset(s, ["motors", "acc", "gyro"])
    # host = HOST_OFFSET + (fw - fw0) + latency, latency uniform in [2, 6] ms
    assert off - (HOST_OFFSET - fw0) == pytest.approx(0.004, abs=0.0005)


@pytest.mark.parametrize(("window", "first", "count"), [
    (None, 0, None),                  # all: from the last stream's first sample
    ((10.0, 12.0), 474, 100),         # host seconds -> firmware 9.496..11.496
    ("landing", 2224, None),          # a phase by name, until the end of the log
])
def test_windows(flight, window, first, count) -> None:
    d = load_session(flight.path, window=window, detrend=None)
    assert np.array_equal(d.u[0], held(flight.values["motors"], flight.dropped["motors"],
                                       np.array([first]))[0])
    if count is not None:
        assert d.n_samples == count
    else:  # runs to the end: the last sample logged by every stream
        assert first + d.n_samples in (2500, 2499)


def test_selection_by_field_and_variable(flight) -> None:
    d = load_session(flight.path, inputs=["motors.m2", "motor.m4"], outputs=["gyro"])
    assert d.input_names == ("motor.m2", "motor.m4") and d.n_outputs == 3
    both = [g[0] for g in load_sessions([flight.path, flight.path], outputs=["gyro.z"],
                                        window="excitation", dt=0.02)]
    assert len(both) == 2 and both[0].n_samples == both[1].n_samples == N_EXC


@pytest.mark.parametrize(("kwargs", "exc", "words"), [
    ({"inputs": ["baro"]}, DataError, ["f.h5", "'baro'", "log streams are"]),
    ({"outputs": ["gyro.q"]}, DataError, ["'gyro.q'"]),
    ({"window": "hover"}, SessionError, ["f.h5", "no phase 'hover'", "excitation"]),
    ({"window": (200.0, 300.0)}, DataError, ["less than one"]),
    ({"inputs": ["gyro.x"], "outputs": ["gyro"]}, DataError, ["both input and output"]),
    ({"detrend": "quadratic"}, ParameterError, ["detrend"]),
])
def test_user_mistakes_are_one_line(flight, kwargs, exc, words) -> None:
    with pytest.raises(exc) as info:
        load_session(flight.path, **kwargs)
    msg = str(info.value)
    assert "\n" not in msg and all(w in msg for w in words), msg


def test_session_without_log_streams(tmp_path) -> None:
    path = tmp_path / "empty.h5"
    spec = log_block_spec(name="motors", variables=[("motor.m1", "uint16_t")], period_s=0.02)
    with SessionWriter(path, streams=[spec, *standard_streams()]) as w:
        w.phase(t=0.0, phase_id=0, name="excitation", kind="excitation")
    with pytest.raises(DataError, match=r"empty\.h5: no log stream or variable 'motors'"):
        load_session(path)


def test_an_aborted_flight_is_said_when_identifying_from_it(tmp_path, caplog) -> None:
    """A flight stopped with Ctrl-C 39 s into a 102 s PRBS was identified from in silence
    (first-day review): its excitation phase ends at the abort."""
    import json

    import h5py

    flight = write_flight(tmp_path / "f.h5", system=known_system(), seed=3, n=600)
    load_session(flight.path, inputs=["motors"], outputs=["gyro"])
    assert "aborted" not in caplog.text
    with h5py.File(flight.path, "r+") as f:
        f.attrs["summary"] = json.dumps({"aborted": True, "cause": "SIGINT received"})
    load_session(flight.path, inputs=["motors"], outputs=["gyro"])
    assert "the flight was aborted (SIGINT received)" in caplog.text
