"""``sysid.identify``: the model ``sysid identify`` chooses, from arrays (no knobs).

>>> import sysid
>>> sel = sysid.identify(sysid.IOData(u=u, y=y, dt=0.01))        # doctest: +SKIP
>>> sel.model, sel.best.order, sel.warnings                       # doctest: +SKIP

Past, future and order are chosen by validation on held-out data (:mod:`sysid.auto`), and
whatever is not given as a keyword: the focus, the direct term (tried where the data show
no feedback), and the method (PARSIM-K tried beside IEM at the chosen horizons). The
:class:`sysid.auto.Selection` says what was chosen and why (``rule``, ``focus_note``,
``feedthrough_note``, ``method_note``, ``warnings``) and holds the model identified again on
all the data (``model``).
"""

from __future__ import annotations

from collections.abc import Sequence

from sysid.auto import Selection, select
from sysid.data import IOData, as_flights
from sysid.errors import ParameterError
from sysid.finish import Focus
from sysid.methods import DEFAULT_METHOD, get_method
from sysid.stability import Stability

__all__ = ["identify"]


def identify(data: IOData | Sequence[IOData], *, method: str | None = None,
             focus: Focus | None = None, feedthrough: bool | None = None,
             stability: Stability = "auto",
             validation: IOData | Sequence[IOData] | None = None,
             pasts: Sequence[int] | None = None, futures: Sequence[int] | None = None,
             orders: Sequence[int] | None = None, workers: int = 1) -> Selection:
    """Identify a model with every setting not given chosen on held-out data.

    Args:
        data: one experiment (``IOData``: u ``(N, m)``, y ``(N, l)``) or several of one
            system (each its own record); without ``validation`` the last 30 % of each
            validates and the rest identifies.
        method: ``"iem"``, ``"parsim-k"`` or ``"po-moesp"``; None: IEM, with PARSIM-K
            tried at the chosen horizons (the smaller order that scores as well wins).
        focus: ``"prediction"`` or ``"simulation"``; None: both tried, the method's default
            kept unless the other is better by more than one standard error.
        feedthrough: estimate D or not; None: the method's default, and a direct term tried
            when the data show no feedback (:mod:`sysid.feedback`).
        stability: ``"auto"``, ``"enforce"`` or ``"free"`` (:mod:`sysid.stability`).
        validation: experiments to validate on instead of the held-out part.
        pasts, futures, orders: the grid (samples, states); None: the default grid, scaled
            to the data's memory.
        workers: processes for the sweep.

    Returns:
        The :class:`~sysid.auto.Selection`; ``.model`` is the ``StateSpaceModel``.
    """
    flights = list(as_flights(data))
    val = None if validation is None else list(as_flights(validation))
    for name, values in (("pasts", pasts), ("futures", futures), ("orders", orders)):
        if values is not None and not len(values):
            raise ParameterError(f"{name}: pass at least one value, or None for the default")
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ParameterError(f"workers={workers!r}; pass a whole number >= 1")
    meth = get_method(DEFAULT_METHOD if method is None else method)
    values: dict[str, object] = {"stability": stability}
    if focus is not None:
        values["focus"] = focus
    if feedthrough is not None:
        values["feedthrough"] = feedthrough
    return select([flights], method=meth, options=meth.options(**values), pasts=pasts,
                  futures=futures, orders=orders, validation=val, workers=workers,
                  choose_focus=focus is None,
                  choose_feedthrough="open-loop" if feedthrough is None else False,
                  choose_method=method is None)
