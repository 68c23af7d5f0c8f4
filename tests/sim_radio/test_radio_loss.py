"""Flights through a lossy emulated radio: the session records the drop counts and link quality
that the injected loss gives.

The air turns lossy as the flight starts (the first setpoint; the connect stays quick), ``loss`` of
every transmission, packet or ack, lost. Known truth, with tolerances from the counts' own spread
(``binomial.py``):

* link quality: cflib records one value per acked transfer, the mean of ``10 (10 - retries)``
  over the last 100; the values whose window lies in the noise average to
  :func:`expected_link_quality` of ``p = (1 - loss)^2`` per attempt, within ``Z sd / sqrt(N)``
  (every transfer weighs at most ``1 / N`` in the mean of ``N`` overlapping windows);
* transfers failing all ARC + 1 attempts: binomial, ``(1 - p)^(ARC + 1)``;
* log packets lost for good: with safelink (current nRF firmware) none, exactly: the dongle
  retries a lost packet, cflib resends a failed transfer and the vehicle keeps a downlink packet
  until confirmed. Without safelink (``safelink_capable=False``: nRF firmware before it) a lost ack
  loses its payload, so each log packet sent in the noise is lost with probability ``loss``: the
  summary's drop count is binomial over those packets.
"""

from __future__ import annotations

import numpy as np
import pytest

from cfsession.reader import open_session
from groundstation.flight import fly_plan
from groundstation.flight.link import install_drivers
from groundstation.sim.crazyradio_usb import emulated_radio
from groundstation.sim.radio_noise import (
    RadioNoise,
    expected_link_quality,
    link_quality_sd,
    retry_distribution,
)

from .backend import SPEED, URI
from .binomial import check_count, check_mean

BLOCKS = ("motors", "acc", "gyro")
WINDOW = 100  # cflib's link quality: mean over the last 100 acked transfers
SLACK = 20  # rows stamped at the first setpoint's time that may precede the noise


@pytest.mark.parametrize("loss", [0.05, 0.3])
@pytest.mark.parametrize("safelink", [True, False], ids=["safelink", "no-safelink"])
def test_injected_loss_is_what_the_session_records(loss, safelink, tmp_path):
    install_drivers()
    with emulated_radio(speed=SPEED, seed=1, vehicles=[{"safelink_capable": safelink}]) as bus:
        dongle, vehicle = bus.dongles[0], bus.vehicles[0]
        before: dict[str, int] = {}

        def noisy_from_take_off(k: int) -> None:
            if k == 0:
                with dongle.lock:
                    before["transfers"] = dongle.stats.transfers
                    dongle.set_noise(RadioNoise(loss=loss))

        result = fly_plan(plan="hover-check", out=tmp_path, uri=URI, tick_hook=noisy_from_take_off)
    assert not result.aborted, result.cause
    s = open_session(result.path)
    assert s.closed_cleanly and not s.problems
    t0 = s["phases"].data["host_time"][0]  # the first setpoint, sent right after the noise began
    p, arc = (1.0 - loss) ** 2, dongle.arc
    # link quality as recorded, the windows inside the noise
    link = s["link"].data
    rows = link[np.isfinite(link["quality"])]
    q = rows["quality"][np.searchsorted(rows["host_time"], t0, side="right") + WINDOW + SLACK:]
    assert len(q) >= 1000, len(q)
    check_mean(float(q.mean()), n=len(q), expected=expected_link_quality(p_attempt=p, arc=arc),
               sd=link_quality_sd(p_attempt=p, arc=arc), what="recorded link quality")
    # transfers that failed every attempt (cflib sent them again)
    stats = dongle.stats
    check_count(stats.failed, n=stats.transfers - before["transfers"],
                p=retry_distribution(p_attempt=p, arc=arc)[-1], what="failed transfers")
    # log packets lost for good, as the session's summary counts them
    blocks = s.json_meta("summary")["blocks"]
    dropped = {b: blocks[b]["dropped"] for b in BLOCKS}
    if safelink:
        assert dropped == dict.fromkeys(BLOCKS, 0)
        assert vehicle.duplicates > 0  # acks were lost: the retried packets came twice
    else:
        sent = sum(blocks[b]["expected"] - int((s[b].data["host_time"] < t0).sum())
                   for b in BLOCKS)  # the packets due after the noise began
        check_count(sum(dropped.values()), n=sent, p=loss, what="log packets dropped")
        assert vehicle.duplicates == 0  # nothing to tell duplicates by: all delivered
    assert {b: blocks[b]["received"] for b in BLOCKS} == {b: len(s[b]) for b in BLOCKS}
