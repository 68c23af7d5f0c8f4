"""The public names that moved in the layout redesign (issue 12) still import from their old
paths, as the same objects: ``groundstation.plans``, ``groundstation.session``,
``sysid.excitation`` and ``sysid.cli_types`` re-export from the new homes.

The name lists are the ``__all__`` of the old modules (commit 96ad27a, before the move)."""

from __future__ import annotations

import importlib

import pytest

MOVED = {
    "groundstation.plans": ("groundstation.plan", [
        "SETPOINT_CHANNELS", "SHIPPED_PLANS_DIR", "UNITS", "ExcitationSpec", "Phase", "PhaseSpec",
        "Plan", "Safety", "Schedule", "VehicleLimits", "find_plan", "load_plan", "parse_plan"]),
    "groundstation.session": ("cfsession", [
        "Session", "SessionWriter", "event_rows", "open_session", "standard_streams"]),
    "sysid.excitation": ("groundstation.plan.excitation", [
        "LFSR_TAPS", "ExcitationError", "chirp", "doublet", "mls_bits", "prbs", "prbs_period",
        "prbs_persistence_order", "prbs_shift", "register_length_for_period", "step"]),
    "sysid.cli_types": ("cfcommon.cli", ["FiniteFloat", "check_output"]),
}


@pytest.mark.parametrize("old", sorted(MOVED))
def test_the_old_path_gives_the_same_objects(old):
    new, names = MOVED[old]
    old_module, new_module = importlib.import_module(old), importlib.import_module(new)
    assert sorted(old_module.__all__) == sorted(names)
    for name in names:
        assert getattr(old_module, name) is getattr(new_module, name), name
    namespace: dict[str, object] = {}
    exec(f"from {old} import *", namespace)  # what a star import of the old path binds
    assert {n for n in namespace if n != "__builtins__"} == set(names)


def test_the_old_excitation_path_refuses_names_it_never_had():
    import sysid.excitation

    with pytest.raises(AttributeError, match=r"sysid\.excitation.*has no attribute 'iem'"):
        _ = sysid.excitation.iem
    with pytest.raises(ImportError):
        exec("from sysid.excitation import Plan", {})


def test_old_paths_work_end_to_end(tmp_path):
    """A plan loaded and a session written and read through the old paths."""
    from groundstation.plans import load_plan
    from groundstation.session import SessionWriter, open_session, standard_streams
    from sysid.excitation import prbs, prbs_period

    plan = load_plan("prbs-3axis")
    assert plan.compile().thrust.shape == (plan.n_setpoints,)
    n = prbs_period(register_length=5, clock_period=2)
    u = prbs(register_length=5, clock_period=2, amplitude=3.0, n_samples=n)
    assert n == 62 and set(u) == {-3.0, 3.0} and u.sum() == 3.0 * 2  # 16 chips up, 15 down
    path = tmp_path / "s.h5"
    with SessionWriter(path, streams=standard_streams(), metadata={"uri": "sim://0"}) as w:
        w.event(t=0.5, text="hello")
    assert [e.text for e in open_session(path).events()] == ["hello"]
