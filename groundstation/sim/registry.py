"""One simulation per ``sim://`` address: powered on by the first URI that reaches it (the
link's driver or a scheduler's clock), reachable for inspection after it powered off."""

from __future__ import annotations

import threading

from groundstation.errors import LinkError
from groundstation.sim.simulator import Simulator
from groundstation.sim.uri import parse_uri

__all__ = ["close_all", "instance", "running_addresses", "simulator_for_uri"]

_registry: dict[str, Simulator] = {}
_registry_lock = threading.Lock()


def simulator_for_uri(uri: str) -> Simulator:
    """The running simulation behind ``uri``, powered on (from the URI's options) if there is
    none."""
    opts = parse_uri(uri)
    with _registry_lock:
        sim = _registry.get(opts.address)
        if sim is None or not sim.running:
            sim = Simulator(address=opts.address, speed=opts.speed, seed=opts.seed,
                            auto_arm=opts.auto_arm)
            _registry[opts.address] = sim
        return sim


def instance(uri: str) -> Simulator:
    """The simulation behind ``uri`` (running, or the last one, powered off, for inspection)."""
    address = parse_uri(uri).address
    with _registry_lock:
        sim = _registry.get(address)
    if sim is None:
        raise LinkError(f"no simulation for {uri!r}; connect to it (or get its clock) first")
    return sim


def running_addresses() -> list[str]:
    """Addresses ``N`` of the simulations running now (what a ``sim://`` scan finds)."""
    with _registry_lock:
        return [a for a, s in _registry.items() if s.running]


def close_all() -> None:
    """Power off every simulation (tests call this in teardown)."""
    with _registry_lock:
        sims = list(_registry.values())
    for sim in sims:
        sim.close()
