"""Noise on the emulated air, seen through cflib's own ``Crazyradio``: the retries in each ack's
status byte, the failed transfers and the link quality follow the retry distribution of the
injected noise (:mod:`groundstation.sim.radio_noise`); bit errors cost more on longer packets.

Known truth: the injected ``loss`` and ``bit_error_rate``, the ESB packet's bits on air
(``65 + 8 n``) and the ARC the dongle reports back; tolerances from the counts' own spread
(``binomial.py``)."""

from __future__ import annotations

import numpy as np
import pytest
from cflib.drivers.crazyradio import Crazyradio

from groundstation.sim.crazyradio_usb import emulated_radio
from groundstation.sim.radio_noise import (
    RadioNoise,
    expected_link_quality,
    link_quality_sd,
    retry_distribution,
)

from .backend import SPEED
from .binomial import check_count, check_mean

N_TRANSFERS = 2000
SINK = 0xFE  # CRTP link control, channel 2 (sink): the vehicle takes it and answers nothing


@pytest.mark.parametrize(("noise", "n_bytes"), [
    ({"loss": 0.3}, 2),
    ({"bit_error_rate": 2e-3}, 2),
    ({"bit_error_rate": 2e-3}, 32),
], ids=["loss-30%", "bit-errors-2-bytes", "bit-errors-32-bytes"])
def test_noise_gives_the_retry_statistics_of_a_real_radio(noise, n_bytes):
    with emulated_radio(speed=SPEED, seed=2, **noise) as bus:
        radio = Crazyradio()  # cflib's driver: ARC 3, as cflib sets it
        radio.set_channel(80)
        acks = [radio.send_packet((SINK,) + (0,) * (n_bytes - 1)) for _ in range(N_TRANSFERS)]
        radio.close()
    dongle = bus.dongles[0]
    arc, stats = dongle.arc, dongle.stats
    assert arc == 3
    acked = [a for a in acks if a.ack]
    # Empty acks (the lengths the model assumes), except for the vehicle's boot banner: when its
    # simulation thread first runs after the radio attached (a loaded host), the console text
    # (4 CONSOLE packets, port 0) rides on the first acks; a loaded clean-clone run saw it.
    odd = [bytes(a.data) for a in acked if len(a.data) != 1]
    assert len(odd) <= 4 and all(d[0] >> 4 == 0 for d in odd), odd
    p = RadioNoise(**noise).p_attempt(up_bytes=n_bytes, ack_bytes=1)
    # Acked after k retries with (1 - p)^k p, failed after ARC + 1 attempts with (1 - p)^(ARC+1):
    # cflib's view (status byte) per bin, and the dongle's own count agrees with it.
    seen = [sum(1 for a in acked if a.retry == k) for k in range(arc + 1)]
    seen.append(N_TRANSFERS - len(acked))
    assert stats.histogram(arc=arc) == seen
    for k, (count, pk) in enumerate(zip(seen, retry_distribution(p_attempt=p, arc=arc),
                                        strict=True)):
        check_count(count, n=N_TRANSFERS, p=pk, what="failed" if k > arc else f"{k} retries")
    # cflib's link quality, 10 (10 - retries) over the acked transfers
    quality = 10 * (10 - np.mean([a.retry for a in acked]))
    check_mean(quality, n=len(acked), expected=expected_link_quality(p_attempt=p, arc=arc),
               sd=link_quality_sd(p_attempt=p, arc=arc), what="link quality")
    assert stats.link_quality() == pytest.approx(quality)
    # the cause: fixed loss drops packets whole, bit errors fail their CRC
    if "loss" in noise:
        assert stats.lost > 0 and stats.corrupted == 0
    else:
        assert stats.corrupted > 0 and stats.lost == 0


def test_bit_errors_cost_more_on_longer_packets():
    """What a real link shows and a fixed loss does not: at one bit error rate, 32-byte packets
    need more retries than 2-byte ones (73 vs 321 bits up: p = 0.75 vs 0.45 per attempt)."""
    noise = RadioNoise(bit_error_rate=2e-3)
    short, long_ = (noise.p_attempt(up_bytes=n, ack_bytes=1) for n in (2, 32))
    assert short == pytest.approx(0.998 ** 81 * 0.998 ** 73) and long_ < short
    gap = expected_link_quality(p_attempt=short) - expected_link_quality(p_attempt=long_)
    spread = max(link_quality_sd(p_attempt=p) for p in (short, long_)) / np.sqrt(N_TRANSFERS)
    assert gap > 20 * spread  # the two parametrised runs above cannot both pass on one model


@pytest.mark.parametrize("bad", [{"loss": 1.5}, {"loss": float("nan")},
                                 {"bit_error_rate": -0.1}])
def test_noise_outside_zero_to_one_is_refused(bad):
    with pytest.raises(ValueError, match="must be a number in"), emulated_radio(**bad):
        pass
