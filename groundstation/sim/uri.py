"""The options of a ``sim://`` URI.

URI: ``sim://N?speed=20&seed=3&drop=0.05&latency_ms=20&cut_at=12.5&autoarm=0`` (every option
optional):

====================  ==========================================================================
``N``                 which simulated vehicle (default 0); one simulation per ``N`` at a time
``speed``             simulation seconds per wall-clock second (default 1, at most 100; ``inf``:
                      flat out)
``seed``              the vehicle's random seed (default 0)
``drop``              fraction of log data packets lost on the way down (default 0)
``latency_ms``        delay, in simulation ms, added to every packet the link returns
``cut_at``            simulation time, s, at which the link goes silent for good
``autoarm``           1 (default): armed from power-on, as a Crazyflie 2.x; 0: armed only on
                      request, as a Crazyflie Brushless (``fly --arm``)
====================  ==========================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qsl, urlsplit

from groundstation.errors import LinkError

__all__ = ["MAX_SPEED", "Faults", "SimOptions", "parse_uri"]

MAX_SPEED = 100.0
"""The largest finite ``speed`` (the simulator manages ~45x flat out; ``inf`` asks for that)."""


@dataclass
class Faults:
    """Link faults: ``drop`` fraction of log packets, ``latency_ms`` added to every packet the
    link returns (simulation ms), the link cut for good at ``cut_at`` simulation seconds."""

    drop: float = 0.0
    latency_ms: float = 0.0
    cut_at: float | None = None


@dataclass
class SimOptions:
    """A parsed ``sim://`` URI."""

    address: str = "0"
    speed: float = 1.0
    seed: int = 0
    faults: Faults | None = None
    auto_arm: bool = True


def _number(name: str, text: str, *, kind: type, low: float, high: float = math.inf) -> Any:
    try:
        value = kind(text)
    except ValueError:
        value = None
    if value is None or not (low <= value <= high) or (kind is float and math.isnan(value)):
        raise LinkError(f"sim:// option {name}={text!r} must be a number in [{low}, {high}]; "
                        "e.g. sim://0?speed=20&seed=3")
    return value


def parse_uri(uri: str) -> SimOptions:
    """The options of a ``sim://`` URI (:class:`LinkError` naming a bad option)."""
    parts = urlsplit(uri)
    if parts.scheme != "sim":
        raise LinkError(f"{uri!r} is not a sim:// URI; use e.g. sim://0?speed=20")
    opts, faults = SimOptions(address=(parts.netloc + parts.path).strip("/") or "0"), Faults()
    pairs = parse_qsl(parts.query, keep_blank_values=True)
    twice = sorted({k for i, (k, _) in enumerate(pairs) if k in dict(pairs[:i])})
    if twice:  # the last would win in silence: speed=inf&speed=1 flew in real time
        raise LinkError(f"sim:// option {twice[0]!r} given twice in {uri!r}; give each once")
    for key, text in pairs:
        if key == "speed":
            opts.speed = _number(key, text, kind=float, low=1e-3)
            if MAX_SPEED < opts.speed < math.inf:
                raise LinkError(f"sim:// option speed={text!r} is beyond {MAX_SPEED:g}; the "
                                "simulator manages about 45x flat out: use speed=20, or "
                                "speed=inf for as fast as it can")
        elif key == "seed":
            opts.seed = _number(key, text, kind=int, low=0, high=2**63)
        elif key == "drop":
            faults.drop = _number(key, text, kind=float, low=0.0, high=1.0)
        elif key == "latency_ms":
            faults.latency_ms = _number(key, text, kind=float, low=0.0, high=60_000.0)
        elif key == "cut_at":
            faults.cut_at = _number(key, text, kind=float, low=0.0)
        elif key == "autoarm":
            opts.auto_arm = bool(_number(key, text, kind=int, low=0, high=1))
        else:
            raise LinkError(f"unknown sim:// option {key!r}; "
                            "use speed, seed, drop, latency_ms, cut_at or autoarm")
    opts.faults = faults
    return opts
