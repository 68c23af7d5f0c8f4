"""One registry of methods with typed options serves the API, order selection and the CLI."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import sysid
from sysid.cli import main
from sysid.errors import ParameterError
from sysid.methods import METHODS, IEMOptions, MOESPOptions, get_method
from tests.sysid.systems import open_loop, random_stable_system


@pytest.fixture(scope="module")
def data() -> sysid.IOData:
    rng = np.random.default_rng(5)
    system = random_stable_system(n_states=3, n_inputs=2, n_outputs=2, rng=rng)
    return open_loop(system, n_samples=1200, rng=rng, noise_std=0.1).data


def test_options_are_frozen_and_their_literals_checked() -> None:
    opts = IEMOptions(feedthrough=True, focus="simulation")
    with pytest.raises(dataclasses.FrozenInstanceError):
        opts.focus = "prediction"  # type: ignore[misc]
    with pytest.raises(ParameterError, match=r"IEMOptions.variant='n4sid'"):
        IEMOptions(variant="n4sid")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match=r"MOESPOptions.stability='never'"):
        MOESPOptions(stability="never")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match=r"feedthrough='yes'"):
        IEMOptions(feedthrough="yes")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match=r"po-moesp has no option\(s\) \['bk_method'\]"):
        get_method("po_moesp").options(bk_method="state")
    with pytest.raises(ParameterError, match="takes IEMOptions, not MOESPOptions"):
        get_method("iem").identify(None, order=2, past=5, future=5, options=MOESPOptions())


def test_registry_identifies_as_the_functions_do(data) -> None:
    for name, fn in (("iem", sysid.iem), ("po-moesp", sysid.po_moesp)):
        meth = get_method(name)
        got = meth.identify(data, order=3, past=8, future=6,
                            options=meth.options(feedthrough=True))
        np.testing.assert_allclose(got.A, fn(data, order=3, past=8, future=6,
                                              feedthrough=True).A, rtol=1e-12, atol=1e-12)
        sv = sysid.singular_values(data, past=8, future=6, method=name, feedthrough=True)
        np.testing.assert_allclose(sv, got.provenance["singular_values"], rtol=1e-9)


def test_cli_offers_exactly_the_registered_methods() -> None:
    for command in ("identify", "order", "sweep"):
        choice = next(p for p in main.commands[command].params if p.name == "method").type
        assert sorted(choice.choices) == sorted(METHODS)
