"""DaISy open-loop sets, the project against SIPPY in the same run: ``python -m bench daisy``.

Protocol of ``shared/reference/benchmarks.md`` (``tests/sysid/daisy.py``): means removed,
first 2/3 identify, last 1/3 validate by simulation from x0 = 0, mean fit over outputs, best
over orders 2..10 among stable models, past = future = 20, D estimated. The project's best is
over IEM, PO-MOESP and PARSIM-K with prediction and simulation focus (and their PEM refinement with
``BENCH_DAISY_PEM=1``: slow on cstr); SIPPY 1.0.1's over N4SID, MOESP, CVA, PARSIM-K/S/P.
Target (issue 10): project >= SIPPY on every set. The last column is what the no-knobs
selection chooses (``sysid.identify(ident)``, as ``sysid identify`` with no settings: IEM,
held-out selection on the identification part, focus chosen, a direct term tried where the
feedback test finds no feedback, PARSIM-K tried at the chosen horizons), by the protocol.
``BENCH_DAISY_SETS=dryer,cstr`` picks sets; ``BENCH_DAISY_EXTRA`` adds other sets' files by the
same protocol (``NAME=FILE:INPUTS:OUTPUTS;...``, columns 1-based: e.g. DaISy's
``cd_arm=CD_player_arm.dat:1,2:3,4;glassfurnace=glassfurnace.dat:2,3,4:5,6,7,8,9,10``); SIPPY's
figure for those comes from the run (none without SIPPY). A set too short for the protocol's
horizons prints the project's refusal.
"""

from __future__ import annotations

import contextlib
import io
import os
import time
import warnings

import numpy as np

import sysid
from tests.sysid.daisy import (
    DAISY,
    EXTRA,
    SETS,
    SIPPY_BEST,
    best_model,
    load,
    parse_extra,
    protocol_fit,
)

__all__ = ["main"]

SIPPY_METHODS = ("N4SID", "MOESP", "CVA", "PARSIM-K", "PARSIM-S", "PARSIM-P")


CLASSIC = ("N4SID", "MOESP", "CVA")
FIXED_K = ("PARSIM-S", "PARSIM-P")
"""SIPPY 1.0.1's PARSIM-S/P fit B_K, D and x0 by least squares on predictor simulations that
each carry the response to K y (K fixed), so the fitted parameters also scale that response
(``simulations_sequence_S``); docs/sysid.md. Their figures are printed apart."""


def _sippy_best(name: str) -> tuple[tuple[float, str], tuple[float, str], tuple[float, str]]:
    """SIPPY's best protocol fit on the set and the method/order that reached it: over all
    its subspace methods, over the classic three (N4SID, MOESP, CVA), and over all but
    PARSIM-S/P (:data:`FIXED_K`)."""
    from sippy_unipi import system_identification

    ident, val = load(name)
    best = (-np.inf, "")
    classic = (-np.inf, "")
    sound = (-np.inf, "")
    for method in SIPPY_METHODS:
        for n in range(2, 11):
            try:
                with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
                    warnings.simplefilter("ignore")
                    sys_id = system_identification(
                        ident.y.T.copy(), ident.u.T.copy(), method, centering="None",
                        SS_f=20, SS_p=20, SS_fixed_order=n, SS_D_required=True)
                model = sysid.StateSpaceModel(A=sys_id.A, B=sys_id.B, C=sys_id.C, D=sys_id.D)
                fit = protocol_fit(model, val)
            except Exception:  # SIPPY failures (SVD, shapes) count as misses
                continue
            if np.isfinite(fit) and fit > best[0]:
                best = (fit, f"{method} n={n}")
            if method in CLASSIC and np.isfinite(fit) and fit > classic[0]:
                classic = (fit, f"{method} n={n}")
            if method not in FIXED_K and np.isfinite(fit) and fit > sound[0]:
                sound = (fit, f"{method} n={n}")
    return best, classic, sound


def _po_moesp_best(name: str) -> float:
    """PO-MOESP (standard variant), best over both focus choices and orders 2..10 (NaN when
    every model is refused or unstable)."""
    ident, val = load(name)
    fits = []
    for n in range(2, 11):
        for focus in ("simulation", "prediction"):
            try:
                model = sysid.po_moesp(ident, order=n, past=20, future=20, focus=focus)
            except sysid.SysIdError:
                continue
            fits.append(protocol_fit(model, val))
    return float(np.nanmax(fits)) if np.isfinite(fits).any() else np.nan


def _no_knobs(name: str) -> tuple[float, str]:
    """What :func:`sysid.identify` chooses with no settings given (the no-knobs path of the
    CLI's ``sysid identify``: held-out selection, focus chosen, a direct term tried only where
    the feedback test finds none, PARSIM-K tried), scored by the protocol."""
    ident, val = load(name)
    try:
        sel = sysid.identify(ident)
    except sysid.SysIdError as exc:
        return np.nan, f"refused: {exc}"
    b = sel.best
    d = " D" if sel.model.provenance.get("feedthrough") else ""
    d += " pk" if sel.model.provenance.get("method") == "parsim-k" else ""
    return protocol_fit(sel.model, val), f"p={b.past} f={b.future} n={b.order}{d}"


def main() -> int:
    if not DAISY.is_dir():
        print(f"DaISy sets not found at {DAISY}")
        return 1
    try:
        import sippy_unipi  # noqa: F401
        have_sippy = True
    except ImportError:
        have_sippy = False
        print("sippy_unipi not installed (make bench installs it): SIPPY column from "
              "benchmarks.md")
    pem = os.environ.get("BENCH_DAISY_PEM", "0") == "1"
    try:
        EXTRA.update(parse_extra(os.environ.get("BENCH_DAISY_EXTRA", "")))
    except ValueError as exc:
        print(f"error: BENCH_DAISY_EXTRA: {exc}")
        return 2
    missing = [f"{name} ({path})" for name, (path, _, _) in EXTRA.items() if not path.is_file()]
    if missing:
        print(f"error: BENCH_DAISY_EXTRA: no such file: {', '.join(missing)}")
        return 2
    wanted = [s for s in os.environ.get("BENCH_DAISY_SETS", ",".join([*SETS, *EXTRA])).split(",")
              if s]
    unknown = [s for s in wanted if s not in SETS and s not in EXTRA]
    if unknown:
        print(f"error: BENCH_DAISY_SETS: unknown set(s) {unknown}; known: {[*SETS, *EXTRA]}")
        return 2
    print(f"{'set':15s} {'project':>8s} {'(how)':28s} {'SIPPY':>8s} {'(how)':16s} "
          f"{'diff':>6s} {'t_proj':>7s} {'t_sippy':>7s} {'PO-MOESP':>8s} "
          f"{'SIPPY N4SID/MOESP/CVA':>22s} {'SIPPY w/o PARSIM-S/P':>22s} "
          f"{'no knobs':>8s} {'(chose)':16s}")
    ok = ok_moesp = True
    for name in wanted:
        t0 = time.perf_counter()
        fit, label, order, _ = best_model(name, pem=pem)
        t_proj = time.perf_counter() - t0
        t0 = time.perf_counter()
        if have_sippy:
            (s_fit, s_how), (c_fit, c_how), (k_fit, k_how) = _sippy_best(name)
        else:
            (s_fit, s_how), (c_fit, c_how), (k_fit, k_how) = (
                (SIPPY_BEST.get(name, np.nan), "benchmarks.md"), (np.nan, ""), (np.nan, ""))
        t_sippy = time.perf_counter() - t0
        diff = round(fit, 2) - round(s_fit, 2)  # figures to 0.01 %, as benchmarks.md has them
        # a refusal (NaN) meets the target only on a set added by BENCH_DAISY_EXTRA too short
        # for the protocol's horizons; on the shared six it is a regression. A figure where
        # SIPPY has none (all its methods failed) meets it.
        ok &= (diff >= 0 or not np.isfinite(s_fit)) if np.isfinite(fit) else name not in SETS
        moesp = _po_moesp_best(name)
        auto_fit, auto_how = _no_knobs(name)
        ok_moesp &= moesp >= 0 and not moesp < c_fit - 1.0  # refused (NaN): not met
        how = label + f" n={order}" if np.isfinite(fit) else label  # refused: the reason
        print(f"{name:15s} {fit:8.2f} {how:28s} {s_fit:8.2f} {s_how:16s} "
              f"{diff:+6.2f} {t_proj:6.1f}s {t_sippy:6.1f}s {moesp:8.2f} "
              f"{c_fit:8.2f} {c_how:13s} {k_fit:8.2f} {k_how:13s} {auto_fit:8.2f} {auto_how:16s}",
              flush=True)
    print("target: project >= SIPPY on every set:", "met" if ok else "NOT met")
    print("target: PO-MOESP >= 0 and >= SIPPY's best N4SID/MOESP/CVA - 1 on every set:",
          "met" if ok_moesp else "NOT met")
    return 0
