"""The identification methods, in one registry used by the CLI, order selection and sweeps.

Each :class:`Method` names its function, its options (a frozen dataclass whose ``Literal``
fields are checked when it is made), how it computes the singular values that set the order,
and whether a horizon grid can share one factor among the futures of a past
(:mod:`sysid.grid`: IEM can, PO-MOESP cannot).

>>> from sysid.methods import get_method
>>> iem = get_method("iem")
>>> model = iem.identify(data, order=8, past=60, future=17,
...                      options=iem.options(feedthrough=False))  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from sysid.data import IOData
from sysid.errors import ParameterError
from sysid.factor import DataProducts
from sysid.finish import Focus
from sysid.iem import iem, iem_signals
from sysid.model import StateSpaceModel
from sysid.moesp import moesp_factor, po_moesp
from sysid.parsim import parsim_k, parsim_k_singular_values
from sysid.stability import Stability

__all__ = ["DEFAULT_METHOD", "METHODS", "IEMOptions", "MOESPOptions", "Method", "MethodName",
           "Options", "ParsimOptions", "get_method", "method_loggers"]

MethodName = Literal["iem", "po-moesp", "parsim-k"]
#: The method the API and the command line use when none is named.
DEFAULT_METHOD: MethodName = "iem"


def _check_literals(obj: object) -> None:
    """Raise :class:`ParameterError` for a field whose value is not one its type allows."""
    hints = typing.get_type_hints(type(obj))
    for f in dataclasses.fields(obj):  # type: ignore[arg-type]
        value = getattr(obj, f.name)
        allowed: list[Any] = []
        for part in typing.get_args(hints[f.name]) or (hints[f.name],):
            allowed += typing.get_args(part) if typing.get_origin(part) is Literal else [part]
        literals = [a for a in allowed if not isinstance(a, type)]
        types = tuple(a for a in allowed if isinstance(a, type))
        if value in literals or (types and isinstance(value, types)):
            continue
        if bool in types:
            raise ParameterError(f"{type(obj).__name__}.{f.name}={value!r}; pass True or False"
                                 + (" (or None)" if type(None) in types else ""))
        raise ParameterError(f"{type(obj).__name__}.{f.name}={value!r}; use one of "
                             f"{[a if not isinstance(a, type) else a.__name__ for a in allowed]}")


class _Checked:
    """Options whose fields are checked against their types when made."""

    def __post_init__(self) -> None:
        _check_literals(self)


@dataclass(frozen=True)
class IEMOptions(_Checked):
    """Options of :func:`sysid.iem` (see there); None picks the variant's preset."""

    feedthrough: bool = False
    variant: Literal["consistent", "thesis"] = "consistent"
    focus: Focus = "prediction"
    stability: Stability = "auto"
    bk_method: Literal["state", "thesis"] | None = None
    weighting: Literal["data", "none"] | None = None
    refine: bool | None = None
    pem: bool = False


@dataclass(frozen=True)
class MOESPOptions(_Checked):
    """Options of :func:`sysid.po_moesp`."""

    feedthrough: bool = True
    variant: Literal["standard", "thesis"] = "standard"
    focus: Focus = "simulation"
    stability: Stability = "auto"
    pem: bool = False


@dataclass(frozen=True)
class ParsimOptions(_Checked):
    """Options of :func:`sysid.parsim.parsim_k`."""

    feedthrough: bool = True
    focus: Focus = "prediction"
    stability: Stability = "auto"
    pem: bool = False


Options = IEMOptions | MOESPOptions | ParsimOptions


def _iem_sv(products: DataProducts, options: IEMOptions) -> np.ndarray:
    gamma_lp, sig = iem_signals(products, feedthrough=options.feedthrough)
    weighting = options.weighting or ("none" if options.variant == "thesis" else "data")
    o = gamma_lp @ sig.zp / np.sqrt(sig.n_columns) if weighting == "data" else gamma_lp
    return np.linalg.svd(o, compute_uv=False)


def _moesp_sv(products: DataProducts, options: MOESPOptions) -> np.ndarray:
    l4, _, _ = moesp_factor(products)
    return np.linalg.svd(l4 / np.sqrt(products.n_columns), compute_uv=False)


def _parsim_sv(products: DataProducts, options: ParsimOptions) -> np.ndarray:
    return parsim_k_singular_values(products)


@dataclass(frozen=True)
class Method:
    """One identification method: its function, options and grid behaviour."""

    name: MethodName
    function: Callable[..., StateSpaceModel]
    options_type: type[IEMOptions] | type[MOESPOptions] | type[ParsimOptions]
    sv_function: Callable[[DataProducts, Any], np.ndarray]
    shares_futures: bool
    description: str

    def options(self, **kwargs: Any) -> Options:
        """Typed options from keywords; an unknown keyword is a one-line error."""
        known = self.option_names
        unknown = sorted(set(kwargs) - known)
        if unknown:
            raise ParameterError(f"{self.name} has no option(s) {unknown}; its options are "
                                 f"{sorted(known)}")
        return self.options_type(**kwargs)

    def _checked(self, options: Options | None) -> Options:
        if options is None:
            return self.options_type()
        if not isinstance(options, self.options_type):
            raise ParameterError(f"{self.name} takes {self.options_type.__name__}, not "
                                 f"{type(options).__name__}")
        return options

    def identify(self, data: IOData | Sequence[IOData] | None, *, order: int, past: int,
                 future: int, options: Options | None = None,
                 products: DataProducts | None = None) -> StateSpaceModel:
        """The model of ``data`` (or of ``products``, already built for these horizons)."""
        opts = dataclasses.asdict(self._checked(options))
        return self.function(data, order=order, past=past, future=future, products=products,
                             **opts)

    def max_order(self, *, past: int, future: int, n_inputs: int, n_outputs: int) -> int:
        """The largest order the method identifies at these horizons: the rank
        ``min((f - 1) l, p (m + l))`` that :func:`sysid.realize.check_order` enforces."""
        return min((future - 1) * n_outputs, past * (n_inputs + n_outputs))

    @property
    def option_names(self) -> frozenset[str]:
        """The fields of the method's options."""
        return frozenset(f.name for f in dataclasses.fields(self.options_type))

    def sv_options(self, *, feedthrough: bool | None = None,
                   weighting: Literal["data", "none"] = "data") -> Options:
        """Options of the order-selection SVD (:meth:`singular_values`): ``feedthrough``
        (None: the method's default) and ``weighting`` where the method's singular values
        have one (IEM: ``"data"`` or ``"none"``); a method without it (PO-MOESP, whose
        ``[L42 L43]`` is not weighted) ignores ``weighting``."""
        kwargs: dict[str, Any] = {} if feedthrough is None else {"feedthrough": feedthrough}
        if "weighting" in self.option_names:
            kwargs["weighting"] = weighting
        return self.options(**kwargs)

    def singular_values(self, products: DataProducts, *, options: Options | None = None
                        ) -> np.ndarray:
        """The singular values whose gap suggests the order (:mod:`sysid.order`)."""
        return self.sv_function(products, self._checked(options))


METHODS: dict[str, Method] = {
    "iem": Method(name="iem", function=iem, options_type=IEMOptions, sv_function=_iem_sv,
                  shares_futures=True,
                  description="Innovation Estimation Method (closed loop, estimates K)"),
    "po-moesp": Method(name="po-moesp", function=po_moesp, options_type=MOESPOptions,
                       sv_function=_moesp_sv, shares_futures=False,
                       description="PO-MOESP (open loop; biased under feedback)"),
    "parsim-k": Method(name="parsim-k", function=parsim_k, options_type=ParsimOptions,
                       sv_function=_parsim_sv,  # module level: workers receive it pickled
                       shares_futures=False,
                       description="PARSIM-K (closed loop, predictor form; as SIPPY's)"),
}


def get_method(name: str | Method) -> Method:
    """The registered method ``name``, in any case (``"PO-MOESP"`` as the literature writes it,
    ``"po_moesp"`` as the function is named); an unknown name is a one-line
    :class:`ParameterError` listing the registered names."""
    if isinstance(name, Method):
        return name
    key = str(name).replace("_", "-").lower()
    if key not in METHODS:
        raise ParameterError(f"method {name!r} is unknown; use one of {sorted(METHODS)}")
    return METHODS[key]


def method_loggers() -> tuple[str, ...]:
    """The loggers of the registered methods' modules (a sweep quiets them while it runs)."""
    return tuple(sorted({m.function.__module__ for m in METHODS.values()}))
