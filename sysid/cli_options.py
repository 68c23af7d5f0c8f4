"""Options several ``sysid`` commands share: ``--method``, ``--focus``, ``--stability``,
``--force``, the stack of a command that makes a model (:func:`model_options`), and the method
with its options as given (:func:`method_options`)."""

from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

import click

from sysid.cli_support import JSON_OPTION, RRD_OPTION, session_options
from sysid.errors import ParameterError
from sysid.finish import FOCUS_MODES
from sysid.methods import DEFAULT_METHOD, METHODS, Method, Options, get_method
from sysid.model_io import MAX_DIMENSION
from sysid.stability import STABILITY_MODES

__all__ = ["FOCUS_OPTION", "FORCE_OPTION", "METHOD_OPTION", "STABILITY_OPTION", "MethodChoice",
           "OneInt", "fixed_option", "method_chosen", "method_options", "model_options"]


class OneInt(click.IntRange):
    """``--order``, ``--past``, ``--future`` of ``identify``, ``order`` and ``batch``: one
    integer. click's own type called ``--order 1:10`` (MATLAB's ``n4sid(data, 1:10)``) "not a
    valid integer range", as if it took ranges written otherwise; several values are
    ``sysid sweep``'s (``sweep_option``, e.g. ``--orders``)."""

    name = "integer"

    def __init__(self, *, sweep_option: str, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.sweep_option = sweep_option

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None
                ) -> Any:
        if isinstance(value, str) and re.fullmatch(r"\s*\d+\s*([:,]\s*\d+\s*)+", value):
            self.fail(f"{value!r}: one value here; to try several, leave the option out (chosen "
                      f"by validation) or use `sysid sweep SESSION {self.sweep_option} {value}`",
                      param, ctx)
        return super().convert(value, param, ctx)


#: The least value and ``sysid sweep``'s option of each setting :func:`fixed_option` makes.
_FIXED = {"order": (1, "--orders"), "past": (1, "--pasts"), "future": (2, "--futures")}
#: The largest value of those that have one: no more states than a model file holds.
_MOST = {"order": MAX_DIMENSION}


def fixed_option(name: Literal["order", "past", "future"], *, help: str) -> Any:
    """``--order``, ``--past`` or ``--future`` fixed to one value (:class:`OneInt`), with the
    command's own ``help``: one rule for their least values and the sweep options they name."""
    least, sweep = _FIXED[name]
    return click.option(f"--{name}", type=OneInt(min=least, max=_MOST.get(name),
                                                 sweep_option=sweep), help=help)


class MethodChoice(click.Choice):
    """``--method``: a name of the registry (:data:`sysid.methods.METHODS`; ``po_moesp`` as
    the function is named works too). An unknown name is :func:`sysid.methods.get_method`'s
    one line, which lists the registered names."""

    name = "method"

    def __init__(self) -> None:
        super().__init__(sorted(METHODS))

    def convert(self, value: Any, param: click.Parameter | None, ctx: click.Context | None
                ) -> str:
        try:
            return get_method(value).name
        except ParameterError as exc:
            self.fail(str(exc), param, ctx)


METHOD_OPTION = click.option(
    "--method", type=MethodChoice(), default=DEFAULT_METHOD,
    help="; ".join(f"{name}: {m.description}" for name, m in METHODS.items()) + ". Default: "
         f"{DEFAULT_METHOD}; where the command chooses the model (identify without all of "
         "--past/--future/--order, sweep, batch) parsim-k is also tried at the chosen horizons "
         "unless --method is given.")
FOCUS_OPTION = click.option(
    "--focus", type=click.Choice(list(FOCUS_MODES)), default=None,
    help="prediction: closed-loop-consistent one-step predictor (default for iem); "
         "simulation: B, D, x0 by output error (default for po-moesp; biased in closed loop).")
STABILITY_OPTION = click.option(
    "--stability", type=click.Choice(list(STABILITY_MODES)), default="auto", show_default=True,
    help="auto: poles just outside the unit circle (|z| <= 1.1) moved inside: to 0.999 near "
         "z = 1 (integrators), reflected elsewhere (oscillations); enforce: all strictly "
         "inside; free: as estimated.")
FORCE_OPTION = click.option("--force", is_flag=True,
                            help="Replace --out if it exists (never an input file).")
#: ``--force`` of a command with both ``--out`` and ``--rrd`` (:func:`model_options`): one
#: flag for both, as both are the same run's results (the model and its report): a rerun
#: that replaces one replaces the other, and two flags would only add a second refusal.
OUT_RRD_FORCE_OPTION = click.option(
    "--force", is_flag=True, help="Replace --out and --rrd if they exist (never an input file).")


def method_chosen() -> bool:
    """Whether the running command may choose the method (``--method`` not given): the
    selection then also tries :data:`sysid.variants.ALTERNATIVE` at its horizons."""
    ctx = click.get_current_context()
    return ctx.get_parameter_source("method") is click.core.ParameterSource.DEFAULT


def model_options(*, out_help: str) -> Callable[[Callable], Callable]:
    """The options of a command that identifies and may save a model (``identify``,
    ``sweep``): ``--focus``, ``--stability``, the session options, ``--out`` (``out_help``),
    ``--force``, ``--json``, ``--rrd``, in that order in ``--help``."""
    out = click.option("--out", type=click.Path(dir_okay=False, path_type=Path), help=out_help)

    def decorate(func: Callable) -> Callable:
        for option in (RRD_OPTION, JSON_OPTION, OUT_RRD_FORCE_OPTION, out, session_options,
                       STABILITY_OPTION, FOCUS_OPTION):
            func = option(func)
        return func

    return decorate


def method_options(name: str, *, feedthrough: bool | None = None, focus: str | None = None,
            stability: str) -> tuple[Method, Options]:
    """The registered method ``name`` and its options as given on the command line (the
    method's defaults for the others)."""
    meth = get_method(name)
    values: dict[str, Any] = {"stability": stability}
    if feedthrough is not None:
        values["feedthrough"] = feedthrough
    if focus is not None:
        values["focus"] = focus
    return meth, meth.options(**values)
