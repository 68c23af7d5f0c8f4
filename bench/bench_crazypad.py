"""Real Crazyflie logs with no knobs: ``python -m bench crazypad`` (issue 11).

Imports ``shared/data/crazypad/controller_E8_log00`` and ``_log01`` (uSD logs, 100 Hz), lets
:func:`sysid.auto.select` choose past, future and order on log00's airborne segments (the
default window; held out: the last 30 % of each), and scores the chosen model on log01's
airborne segments by one-step prediction and 2 s windowed simulation, as ``sysid compare``
does. SIPPY PARSIM-K and MOESP run on the same log00 segments (joined end to end: SIPPY takes
one record) with the same order and horizons, scored the same way. Inputs
``controller.cmd_{thrust,roll,pitch,yaw}``, outputs ``controller.r_{roll,pitch,yaw}`` and
``controller.accelz``; IEM with its default focus and with ``focus="simulation"``.
"""

from __future__ import annotations

import contextlib
import io
import tempfile
import warnings
from pathlib import Path

import numpy as np

import sysid
from groundstation.importers import usd_to_session
from sysid.auto import select
from sysid.methods import get_method
from sysid.session_io import load_sessions
from tests.paths import CRAZYPAD

__all__ = ["main"]

INPUTS = [f"controller.cmd_{a}" for a in ("thrust", "roll", "pitch", "yaw")]
OUTPUTS = [f"controller.r_{a}" for a in ("roll", "pitch", "yaw")] + ["controller.accelz"]


def _sippy(data: list[sysid.IOData], *, method: str, order: int, past: int, future: int,
           template: sysid.StateSpaceModel) -> sysid.StateSpaceModel | None:
    try:
        from sippy_unipi import system_identification
    except ImportError:
        return None
    u = np.vstack([d.u for d in data])
    y = np.vstack([d.y for d in data])
    with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
        warnings.simplefilter("ignore")
        r = system_identification(y.T.copy(), u.T.copy(), method, SS_fixed_order=order,
                                  SS_f=future, SS_p=past)
    k = np.asarray(getattr(r, "K", np.zeros((order, y.shape[1]))))
    return sysid.StateSpaceModel(A=np.asarray(r.A), B=np.asarray(r.B), C=np.asarray(r.C),
                                 D=np.asarray(r.D), K=k, dt=template.dt,
                                 input_names=template.input_names,
                                 output_names=template.output_names)


def _row(label: str, model: sysid.StateSpaceModel | None, val: list[sysid.IOData]) -> None:
    if model is None:
        print(f"  {label:<34} sippy_unipi not installed (pip install -e '.[bench]')")
        return
    one = sysid.compare(model, val, horizon=1, warn=False).fit
    win = sysid.compare(model, val, window=2.0, warn=False).fit

    def fmt(f: np.ndarray) -> str:
        return " ".join(f"{x:7.1f}" if abs(x) < 1e4 else "  diverg" for x in f) + \
            f" | {np.mean(np.clip(f, -999, None)):7.1f}"

    print(f"  {label:<34} 1-step {fmt(one)}   2 s windows {fmt(win)}")


def main() -> int:
    """Print the figures; 0 unless identification fails (skipped without the logs)."""
    if not CRAZYPAD.is_dir():
        print(f"skipped: {CRAZYPAD} not present")
        return 0
    with tempfile.TemporaryDirectory(prefix="crazypad-") as tmp:  # the imports, removed after
        return _figures(Path(tmp))


def _figures(folder: Path) -> int:
    paths = [usd_to_session(source=CRAZYPAD / n, out=folder / f"{n}.h5")
             for n in ("controller_E8_log00", "controller_E8_log01")]
    try:
        ident = load_sessions(paths[:1], inputs=INPUTS, outputs=OUTPUTS)[0]
    except sysid.DataError as exc:
        print(f"skipped: {exc} (the importer marks airborne-N phases on the importers branch)")
        return 0
    val = load_sessions(paths[1:], inputs=INPUTS, outputs=OUTPUTS, dt=ident[0].dt)[0]
    print(f"log00: {len(ident)} airborne segments {[d.n_samples for d in ident]} samples at "
          f"{1 / ident[0].dt:.0f} Hz; log01: {[d.n_samples for d in val]}")
    print(f"  {'fit on log01 [%]':<34} {'':6} " + " ".join(f"{n[-7:]:>7}" for n in OUTPUTS) +
          " |    mean")
    iem = get_method("iem")
    for focus in ("prediction", "simulation"):
        sel = select([ident], method=iem, options=iem.options(focus=focus), choose_method=True)
        b = sel.best
        print(f"IEM focus={focus} (method chosen: {sel.model.provenance['method']}): chose "
              f"past {b.past}, future {b.future}, order {b.order} "
              f"(held-out score {b.score:.1f} %){'; ' if sel.warnings else ''}"
              f"{'; '.join(sel.warnings)}")
        _row("sysid identify (no knobs)", sel.model, val)
        for meth in ("PARSIM-K", "MOESP"):
            _row(f"SIPPY {meth} (same n, p, f)",
                 _sippy(ident, method=meth, order=b.order, past=b.past, future=b.future,
                        template=sel.model), val)
    return 0
