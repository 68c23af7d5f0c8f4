"""sysid.pole_format: the one description of a model's poles (MATLAB ``damp`` conventions)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sysid.pole_format import POLE_COLUMNS, pole_cells, pole_rows, sorted_poles


def test_pole_formatter_follows_matlab_damp():
    dt = 0.02
    wn, zeta = 2 * math.pi * 2.0, 0.3
    s = complex(-zeta * wn, wn * math.sqrt(1 - zeta**2))
    pair = np.exp(np.array([s, s.conjugate()]) * dt)
    rows = pole_rows([0.99, *pair, 1.01, 0.0], dt=dt)
    assert [r["abs"] for r in rows] == sorted((r["abs"] for r in rows), reverse=True)
    unstable, real, a, b, zero = rows  # |z|: 1.01, 0.99, 0.93 (pair), 0
    assert unstable["tau_s"] is None and pole_cells([unstable])[0][-1] == "unstable"
    for r in (a, b):  # a complex pair: its natural frequency and damping ratio
        assert r["freq_hz"] == pytest.approx(2.0) and r["damping"] == pytest.approx(0.3)
        assert r["tau_s"] == pytest.approx(1 / (zeta * wn))
    assert a["im"] < 0 < b["im"]  # conjugates adjacent, negative first
    # a real pole has a natural frequency (not 0.00 Hz) and damping 1
    assert real["freq_hz"] == pytest.approx(-math.log(0.99) / dt / (2 * math.pi))
    assert real["damping"] == 1.0 and real["tau_s"] == pytest.approx(-dt / math.log(0.99))
    assert zero["damping"] == 1.0 and zero["tau_s"] == 0.0
    assert pole_cells([real])[0] == ("1", "0.9900+0.0000j", "0.9900", "0.0", "0.08", "1.000",
                                     "1.99")


def test_a_negative_real_pole_oscillates_at_the_nyquist_frequency():
    """``z = -0.5`` every 0.1 s: s = (ln 0.5 + iπ) / dt, so f_n is above Nyquist's 5 Hz by the
    decay and the damping ratio is small but positive; the angle is 180°."""
    (row,) = pole_rows([-0.5], dt=0.1)
    s = complex(math.log(0.5), math.pi) / 0.1
    assert row["angle_deg"] == pytest.approx(180.0)
    assert row["freq_hz"] == pytest.approx(abs(s) / (2 * math.pi))
    assert row["damping"] == pytest.approx(-s.real / abs(s))
    assert row["tau_s"] == pytest.approx(0.1 / math.log(2))


def test_table_order_is_modulus_then_imaginary_part():
    """Decreasing modulus; at one modulus complex before real, then the imaginary part, so a
    conjugate pair is adjacent with its negative member first."""
    poles = [0.5, 0.3 + 0.2j, 0.3 - 0.2j, -0.9, complex(0, 0.9), complex(0, -0.9), 0.1]
    assert sorted_poles(poles).tolist() == [complex(0, -0.9), complex(0, 0.9), -0.9, 0.5,
                                            0.3 - 0.2j, 0.3 + 0.2j, 0.1]
    # a model's (n,) array or any iterable; the cells number the rows in that order
    cells = pole_cells(pole_rows(np.array(poles), dt=0.01))
    assert [c[0] for c in cells] == [str(i) for i in range(1, 8)]
    assert all(len(c) == len(POLE_COLUMNS) for c in cells)
    assert [c[1] for c in cells[:3]] == ["0.0000-0.9000j", "0.0000+0.9000j", "-0.9000+0.0000j"]


def test_rows_are_plain_json():
    rows = pole_rows([0.95 + 0.1j, 0.95 - 0.1j, 1.2], dt=0.02)
    assert json.loads(json.dumps(rows)) == rows  # floats and None only, no numpy scalars
    assert {type(v) for r in rows for v in r.values()} <= {float, type(None)}


def test_a_pair_stays_adjacent_beside_a_real_pole_of_the_same_modulus_and_zero_is_json():
    import json

    from sysid.pole_format import pole_cells, pole_rows, sorted_poles

    pair = 0.5 * np.exp(1j * np.pi / 3)
    order = sorted_poles([pair, -0.5, np.conj(pair), 0.0, -0.0 + 0.2j, -0.0 - 0.2j])
    assert np.allclose(order[:3], [np.conj(pair), pair, -0.5])
    rows = pole_rows(order, dt=0.02)
    assert rows[-1]["freq_hz"] is None and "Infinity" not in json.dumps(rows)
    cells = pole_cells(rows)
    assert not any(c[1].startswith("-0.0000") for c in cells), cells


def test_huge_parts_keep_the_imaginary_sign() -> None:
    """A pole of a model file from elsewhere at 1 +- 8e302j: four significant digits, and the
    imaginary part still signed after the real one (not "1.00008e+302j")."""
    from sysid.pole_format import pole_cells, pole_number

    assert pole_number(8e302) == "8e+302" and pole_number(-8e302, "+.4f") == "-8e+302"
    assert pole_number(8e302, "+.4f") == "+8e+302" and pole_number(0.5, "+.4f") == "+0.5000"
    cells = pole_cells([{"re": 1.0, "im": 8e302, "abs": 8e302, "angle_deg": 90.0,
                         "freq_hz": None, "damping": 0.0, "tau_s": None}])
    assert cells[0][1:3] == ("1.0000+8e+302j", "8e+302")
