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


def test_unknown_method_is_one_line_listing_the_registry_everywhere(data, tmp_path) -> None:
    """The API and every command with --method refuse an unknown name with the registry's
    one line, which lists every registered name; "po_moesp" (the function's name) works."""
    from click.testing import CliRunner

    names = sorted(METHODS)
    for call in (lambda: get_method("n4sid"),
                 lambda: sysid.sweep(data, pasts=[4], futures=[4], orders=[2], method="n4sid"),
                 lambda: sysid.singular_values(data, past=4, future=4, method="n4sid"),
                 lambda: sysid.information_criteria(data, orders=[2], past=4, future=4,
                                                    method="n4sid")):
        with pytest.raises(ParameterError) as err:
            call()
        assert "\n" not in str(err.value) and all(repr(n) in str(err.value) for n in names)
    commands = [c for c, cmd in main.commands.items()
                if any(p.name == "method" for p in cmd.params)]
    assert {"identify", "order", "sweep", "batch"} <= set(commands)
    for command in commands:
        extra = ["--out", str(tmp_path / "batch")] if command == "batch" else []
        res = CliRunner().invoke(main, [command, str(tmp_path / "missing.h5"), *extra,
                                        "--method", "n4sid"])
        err = res.stderr.strip()
        assert res.exit_code == 2 and err.startswith("error:") and "\n" not in err, res.output
        assert "'n4sid' is unknown" in err and all(repr(n) in err for n in names), err
        # a registered name passes the option (the command then fails on the missing file)
        res = CliRunner().invoke(main, [command, str(tmp_path / "missing.h5"), *extra,
                                        "--method", "po_moesp"])
        assert res.exit_code == 2 and "--method" not in res.stderr, res.stderr


def test_registry_knows_each_methods_order_limit_and_sv_options() -> None:
    from sysid.errors import OrderError
    from sysid.realize import check_order

    for meth in METHODS.values():
        for past, future, m, ell in ((5, 3, 4, 4), (1, 10, 1, 2), (2, 2, 3, 6)):
            top = meth.max_order(past=past, future=future, n_inputs=m, n_outputs=ell)
            check_order(order=top, past=past, future=future, n_inputs=m, n_outputs=ell)
            with pytest.raises(OrderError):
                check_order(order=top + 1, past=past, future=future, n_inputs=m, n_outputs=ell)
    # the weighting of the order-selection SVD is an option of the methods that have one
    assert get_method("iem").sv_options(weighting="none").weighting == "none"
    assert get_method("po-moesp").sv_options(weighting="none") == MOESPOptions()
    assert get_method("po-moesp").sv_options(feedthrough=False).feedthrough is False


@pytest.mark.parametrize(("call", "word"), [
    (lambda d: sysid.iem(d, order=2, past=5, future=5, feedthrough="no"), "feedthrough='no'"),
    (lambda d: sysid.iem(d, order=2, past=5, future=5, refine="no"), "refine='no'"),
    (lambda d: sysid.iem(d, order=2, past=5, future=5, pem="false"), "pem='false'"),
    (lambda d: sysid.po_moesp(d, order=2, past=5, future=5, feedthrough="false"),
     "feedthrough='false'"),
    (lambda d: sysid.parsim_k(d, order=2, past=5, future=5, scale=1), "scale=1"),
    (lambda d: sysid.singular_values(d, past=5, future=5, feedthrough="no"), "feedthrough='no'"),
    (lambda d: get_method("iem").options(refine="no"), "refine='no'"),
])
def test_on_off_options_must_be_bools(data, call, word) -> None:
    """"no" and "false" are true in Python: given to a boolean option they would switch it on
    (feedthrough="no" estimated D, refine="no" refined). Refused in one line naming it."""
    with pytest.raises(ParameterError) as err:
        call(data)
    msg = str(err.value)
    assert "\n" not in msg and word in msg and "True or False" in msg, msg


def test_every_method_reaches_worker_processes(data) -> None:
    """Worker processes receive the method pickled: PARSIM-K's singular values were a lambda,
    so every `--workers 2` run without --method (IEM with PARSIM-K tried beside it) failed
    with a PicklingError traceback after the sweep's work was done."""
    import pickle

    from sysid.auto import select

    for method in METHODS.values():
        assert pickle.loads(pickle.dumps(method)).name == method.name
    iem = get_method("iem")
    sel = select([[data]], method=iem, options=iem.options(), workers=2, choose_method=True,
                 pasts=[4, 8], futures=[4], orders=[2, 3, 4])
    assert sel.model.is_stable and sel.method_note
