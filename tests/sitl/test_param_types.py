"""The parameter types a plan's ``[parameters]`` is checked against before connecting
(``groundstation.plan.param_types.KNOWN_TYPES``) against the real firmware's TOC (pinned SITL
build, read with cflib): every name is there, writable, with that type."""

from __future__ import annotations

from groundstation.plan.param_types import KNOWN_TYPES

from ..sim_crtp.helpers import connect
from . import backend


def test_the_types_known_offline_are_the_real_firmwares():
    try:
        v = backend.start_vehicle()
        with connect(v.uri) as scf:
            toc = {f"{g}.{n}": e for g, d in scf.cf.param.toc.toc.items() for n, e in d.items()}
    finally:
        backend.close_all()
    assert [n for n in KNOWN_TYPES if n not in toc] == []
    assert {n: (t, toc[n].ctype) for n, t in KNOWN_TYPES.items() if toc[n].ctype != t} == {}
    assert [n for n in KNOWN_TYPES if toc[n].get_readable_access() == "RO"] == []
