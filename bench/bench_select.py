"""The no-knobs model choice on 41 synthetic known systems: ``python -m bench select``.

Each case is a random discrete-time system of known order with data generated from it
(:data:`CASES`, deterministic from the case id). The first 2/3 of the record identify, the
last 1/3 validates. For each case:

- **no knobs**: :func:`sysid.auto.select` on the identification part (IEM, and PARSIM-K at
  the chosen horizons: ``choose_method``; past, future,
  order, focus and direct term chosen on its own held-out part);
- **truth**: the chosen model's fit on the *noise-free* output of the validation third, x0
  estimated (``sysid.compare(model, data, x0="estimate")``), mean over outputs, in %;
- **oracle**: the best truth of four fits at the true order (:func:`oracle`);
- **gap** = truth - oracle, in points (negative: the choice lost that much to the oracle).

The summary counts the cases within 2 points of the oracle, the median and mean gap, the
worst five, the dt twins (same samples, only dt differs: :data:`TWIN`) that choose alike,
and the cases whose held-out data cannot rank the models (the selection's warning).
``BENCH_SELECT_CASES=1,2,3`` picks cases (default all 41; about 5-6 min on one core).
Figures: docs/sysid.md, "Score" and "Parsimony".
"""

from __future__ import annotations

import logging
import os
import statistics
import time

import numpy as np
import scipy.linalg
import scipy.signal

import sysid
from sysid.auto import select
from sysid.methods import get_method

__all__ = ["CASES", "TWIN", "main", "make"]

#: (id, order n, inputs m, outputs l, flags, dt [s], input kind, SNR [dB], samples N).
#: Flags: L lightly damped pair(s) (|z| 0.95-0.995; two when n >= 6), I near integrator
#: (real pole 0.998), D feedthrough (D != 0), E innovation form (process noise K e, noise
#: rescaled so the whole output noise is at the SNR), C closed loop (u = r - Kfb y, loop
#: gain 0.5 at DC or less). Inputs (r in closed loop): white, prbs (random hold 1-3 samples),
#: colored (2nd-order Butterworth low-pass at 0.05 of Nyquist), sines (four random
#: frequencies per input). The SNR is per output, on the noise-free output's std.
CASES = [
    (1, 2, 1, 1, "", 0.02, "white", 30, 2000),
    (2, 4, 1, 1, "L", 0.02, "prbs", 30, 3000),
    (3, 6, 2, 2, "", 1.0, "white", 20, 5000),
    (4, 8, 2, 3, "L", 0.001, "colored", 30, 10000),
    (5, 3, 1, 2, "I", 0.02, "prbs", 25, 2000),
    (6, 5, 3, 4, "D", 60.0, "white", 20, 4000),
    (7, 10, 2, 2, "L", 0.02, "white", 40, 20000),
    (8, 2, 1, 1, "", 1.0, "sines", 30, 1000),
    (9, 4, 2, 2, "E", 0.02, "white", 20, 3000),
    (10, 6, 1, 1, "L", 60.0, "prbs", 10, 8000),
    (11, 7, 2, 3, "D", 0.001, "colored", 20, 6000),
    (12, 3, 1, 1, "C", 0.02, "white", 20, 3000),
    (13, 5, 2, 2, "CE", 1.0, "white", 25, 5000),
    (14, 9, 3, 2, "", 0.02, "prbs", 30, 15000),
    (15, 2, 1, 1, "L", 0.02, "white", 10, 300),
    (16, 4, 1, 2, "", 0.001, "sines", 40, 2000),
    (17, 6, 2, 4, "I", 1.0, "white", 30, 6000),
    (18, 8, 1, 1, "", 60.0, "colored", 30, 4000),
    (19, 3, 3, 1, "D", 0.02, "white", 15, 500),
    (20, 10, 3, 4, "L", 1.0, "prbs", 25, 20000),
    (21, 5, 1, 1, "EI", 0.02, "colored", 20, 5000),
    (22, 4, 2, 1, "C", 60.0, "prbs", 30, 2000),
    (23, 7, 1, 3, "LD", 0.02, "white", 35, 8000),
    (24, 2, 2, 2, "D", 1.0, "colored", 20, 800),
    (25, 6, 1, 2, "EL", 0.001, "white", 15, 10000),
    (26, 9, 2, 2, "ID", 0.02, "prbs", 30, 12000),
    (27, 3, 1, 1, "", 0.02, "white", 40, 400),
    (28, 8, 2, 3, "CL", 0.02, "white", 30, 8000),
    (29, 5, 3, 3, "", 60.0, "sines", 30, 3000),
    (30, 4, 1, 1, "LI", 1.0, "colored", 25, 3000),
    (31, 6, 2, 2, "ED", 0.02, "white", 10, 1500),
    (32, 10, 1, 2, "", 0.001, "prbs", 20, 20000),
    # dt twins: the samples of the case in TWIN, only dt differs
    (33, 4, 1, 1, "L", 1.0, "prbs", 30, 3000),
    (34, 4, 1, 1, "L", 0.001, "prbs", 30, 3000),
    (35, 6, 2, 2, "", 0.001, "white", 20, 5000),
    (36, 8, 1, 1, "", 0.02, "colored", 30, 4000),
    (37, 6, 2, 4, "I", 0.001, "white", 30, 6000),
    (38, 4, 1, 1, "LI", 0.001, "colored", 25, 3000),
    (39, 4, 2, 2, "E", 1.0, "white", 20, 3000),
    (40, 10, 1, 2, "", 1.0, "prbs", 20, 20000),
    # size and run time
    (41, 10, 3, 4, "L", 0.02, "colored", 40, 20000),
]
#: twin -> the case whose samples it shares (its seeds); only dt differs.
TWIN = {33: 2, 34: 2, 35: 3, 36: 18, 37: 17, 38: 30, 39: 9, 40: 32}
FIELDS = ("id", "n", "m", "l", "flags", "dt", "input", "snr", "N")


def spec(cid: int) -> dict:
    """The row of :data:`CASES` for ``cid`` as a dict (keys :data:`FIELDS`)."""
    for c in CASES:
        if c[0] == cid:
            return dict(zip(FIELDS, c, strict=True))
    raise KeyError(cid)


def describe(s: dict) -> str:
    """Short description: order, inputs x outputs, flags, input kind, SNR, dt, N."""
    return (f"n{s['n']} {s['m']}x{s['l']} {s['flags'] or '-':2s} {s['input'][:5]:5s} "
            f"{s['snr']:2d}dB dt{s['dt']:g} N{s['N']}")


def _poles(rng: np.random.Generator, n: int, flags: str) -> list[complex]:
    """Near integrator (I), lightly damped pair(s) (L), then ordinary poles: complex pairs
    (|z| 0.4-0.9, probability 0.6) or real (-0.5 to 0.92)."""
    poles: list[complex] = []
    if "I" in flags:
        poles.append(0.998)
    if "L" in flags:
        for _ in range(1 if n < 6 else 2):
            if n - len(poles) >= 2:
                r, th = rng.uniform(0.95, 0.995), rng.uniform(0.05, 1.0)
                poles += [r * np.exp(1j * th), r * np.exp(-1j * th)]
    while len(poles) < n:
        if n - len(poles) >= 2 and rng.random() < 0.6:
            r, th = rng.uniform(0.4, 0.9), rng.uniform(0.1, 2.5)
            poles += [r * np.exp(1j * th), r * np.exp(-1j * th)]
        else:
            poles.append(rng.uniform(-0.5, 0.92))
    return poles


def _a_matrix(rng: np.random.Generator, poles: list[complex]) -> np.ndarray:
    """Real block-diagonal A with these poles, in random coordinates (T = randn + 2 I)."""
    blocks, i = [], 0
    while i < len(poles):
        p = poles[i]
        if abs(np.imag(p)) > 1e-12:
            a, b = np.real(p), np.imag(p)
            blocks.append(np.array([[a, b], [-b, a]]))
            i += 2
        else:
            blocks.append(np.array([[float(np.real(p))]]))
            i += 1
    a = scipy.linalg.block_diag(*blocks)
    t = rng.standard_normal(a.shape) + 2 * np.eye(a.shape[0])
    return t @ a @ np.linalg.inv(t)


def _input(rng: np.random.Generator, kind: str, n_samples: int, m: int) -> np.ndarray:
    if kind == "white":
        return rng.standard_normal((n_samples, m))
    if kind == "prbs":
        hold = rng.integers(1, 4)
        bits = np.sign(rng.standard_normal((n_samples // hold + 1, m)))
        return np.repeat(bits, hold, axis=0)[:n_samples]
    if kind == "colored":
        b, a = scipy.signal.butter(2, 0.05)
        e = rng.standard_normal((n_samples + 200, m))
        return scipy.signal.lfilter(b, a, e, axis=0)[200:] * 5
    if kind == "sines":
        t = np.arange(n_samples)
        u = np.zeros((n_samples, m))
        for j in range(m):
            for _ in range(4):
                u[:, j] += np.sin(rng.uniform(0.01, 1.5) * t + rng.uniform(0, 6.3))
        return u
    raise ValueError(kind)


def make(cid: int) -> dict:
    """Case ``cid``: ``spec``, input ``u``, noisy output ``y``, noise-free output ``yc`` (the
    deterministic part: the response to the applied u), and the true ``A, B, C, D, K``.
    System draws seed 1000 + id, noise 5000 + id (a twin uses its original's id)."""
    s = spec(cid)
    seed = TWIN.get(cid, cid)
    rng = np.random.default_rng(1000 + seed)
    n, m, ell, flags, n_samples = s["n"], s["m"], s["l"], s["flags"], s["N"]
    a = _a_matrix(rng, _poles(rng, n, flags))
    b = rng.standard_normal((n, m))
    c = rng.standard_normal((ell, n))
    d = rng.standard_normal((ell, m)) * 0.5 if "D" in flags else np.zeros((ell, m))
    k = rng.standard_normal((n, ell)) * 0.3 if "E" in flags else np.zeros((n, ell))
    r = _input(rng, s["input"], n_samples, m)
    closed = "C" in flags
    kfb = np.zeros((m, ell))
    if closed:  # no D in the closed-loop cases
        dc_gain = c @ np.linalg.solve(np.eye(n) - a, b) + d
        kfb = rng.standard_normal((m, ell))
        kfb *= 0.5 / max(np.linalg.norm(kfb @ dc_gain, 2), 1e-9)
        while np.max(np.abs(np.linalg.eigvals(a - b @ kfb @ c))) >= 0.99:
            kfb *= 0.5
    e0 = np.random.default_rng(5000 + seed).standard_normal((n_samples, ell))

    def run(scale: np.ndarray | float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        e = e0 * scale
        x, xd = np.zeros(n), np.zeros(n)  # xd: driven by the applied u only
        u = np.zeros((n_samples, m))
        y, yc = np.zeros((n_samples, ell)), np.zeros((n_samples, ell))
        for i in range(n_samples):
            u[i] = r[i] - kfb @ (c @ x + e[i]) if closed else r[i]
            yc[i] = c @ xd + d @ u[i]
            y[i] = c @ x + d @ u[i] + e[i]
            x = a @ x + b @ u[i] + k @ e[i]
            xd = a @ xd + b @ u[i]
        return u, y, yc

    target = run(0.0)[2].std(axis=0) / 10 ** (s["snr"] / 20)  # noise std per output
    scale = target
    if "E" in flags:  # K e also reaches y: rescale until the whole output noise is at the SNR
        for _ in range(3):
            _, y1, yc1 = run(scale)
            scale = scale * target / (y1 - yc1).std(axis=0)
    u, y, yc = run(scale)
    return dict(spec=s, A=a, B=b, C=c, D=d, K=k, u=u, y=y, yc=yc)


def _horizon(n: int, m: int, ell: int, n_id: int) -> int:
    """The oracle's past = future: max(20, 3n), less until 3 Hankel columns per row fit."""
    p = max(20, 3 * n)
    while p > 2 and (n_id - 2 * p + 1) < 3 * 2 * p * (m + ell):
        p -= 1
    return p


def _truth(model: sysid.StateSpaceModel, val: sysid.IOData) -> float:
    return float(np.mean(sysid.compare(model, val, x0="estimate", warn=False).fit))


def oracle(s: dict, ident: sysid.IOData, val: sysid.IOData) -> float:
    """Best truth at the true order, past = future = :func:`_horizon` (less while PO-MOESP
    fails): IEM with its default options, IEM prediction and simulation focus with the true
    direct-term choice, PO-MOESP simulation focus. NaN when all fail."""
    n, has_d = s["n"], "D" in s["flags"]
    p = _horizon(n, s["m"], s["l"], ident.n_samples)
    while p > 2:
        try:
            sysid.po_moesp(ident, order=n, past=p, future=p, focus="simulation")
            break
        except Exception:  # too long a horizon for the data: shorten it
            p -= 1
    iem = get_method("iem")
    fits = {
        "iem": lambda: iem.identify(ident, order=n, past=p, future=p, options=iem.options()),
        "iem_pred": lambda: iem.identify(ident, order=n, past=p, future=p, options=iem.options(
            focus="prediction", feedthrough=has_d)),
        "iem_sim": lambda: iem.identify(ident, order=n, past=p, future=p, options=iem.options(
            focus="simulation", feedthrough=has_d)),
        "moesp_sim": lambda: sysid.po_moesp(ident, order=n, past=p, future=p,
                                            focus="simulation", feedthrough=has_d),
    }
    scores = []
    for fit in fits.values():
        try:
            scores.append(_truth(fit(), val))
        except Exception:  # a failed variant is no candidate
            continue
    scores = [x for x in scores if np.isfinite(x)]
    return max(scores) if scores else float("nan")


def unranked(warnings: tuple[str, ...]) -> bool:
    """Whether the selection warned that its held-out data cannot rank the models."""
    return any("cannot rank the models" in w or "says little" in w for w in warnings)


def run_case(cid: int) -> dict:
    """Select, score and compare with the oracle on case ``cid``."""
    t0 = time.perf_counter()
    g = make(cid)
    s = g["spec"]
    cut = (2 * s["N"]) // 3
    ident = sysid.IOData(u=g["u"][:cut], y=g["y"][:cut], dt=s["dt"])
    val = sysid.IOData(u=g["u"][cut:], y=g["yc"][cut:], dt=s["dt"])
    iem = get_method("iem")
    sel = select([[ident]], method=iem, options=iem.options(), choose_focus=True,
                 choose_feedthrough=True, choose_method=True)
    b = sel.best
    truth = _truth(sel.model, val)
    best = oracle(s, ident, val)
    return dict(case=cid, spec=s, past=b.past, future=b.future, order=b.order,
                focus=str(sel.model.provenance.get("focus")),
                method=str(sel.model.provenance.get("method")),
                D=bool(sel.model.provenance.get("feedthrough")), truth=truth, oracle=best,
                gap=truth - best, warnings=sel.warnings, unranked=unranked(sel.warnings),
                wall=time.perf_counter() - t0)


def choice(r: dict) -> tuple:
    return r["past"], r["future"], r["order"], r["focus"], r["D"], r["method"]


def _summary(rows: list[dict], failed: list[int], wall: float) -> None:
    gaps = sorted((r["gap"], r["case"]) for r in rows if np.isfinite(r["gap"]))
    by_case = {r["case"]: r for r in rows}
    print(f"\n{len(rows)} cases scored" + (f", {len(failed)} failed: {failed}" if failed else ""))
    if gaps:
        g = [x for x, _ in gaps]
        print(f"within 2 points of the oracle: {sum(x >= -2 for x in g)} of {len(g)}")
        print(f"gap: median {statistics.median(g):+.2f}, mean {statistics.mean(g):+.2f}")
        print("worst five: " + ", ".join(f"{c} {x:+.1f}" for x, c in gaps[:5]))
    pairs = [(a, b) for a, b in TWIN.items() if a in by_case and b in by_case]
    alike = [a for a, b in pairs if choice(by_case[a]) == choice(by_case[b])]
    differ = sorted({a for a, _ in pairs} - set(alike))
    print(f"dt twins choosing alike: {len(alike)}/{len(pairs)}"
          + (f" (differ: {differ})" if differ else ""))
    print(f"warned the held-out data cannot rank the models: "
          f"{[r['case'] for r in rows if r['unranked']]}")
    print(f"total wall time {wall:.0f} s")


def main() -> int:
    """Print one line per case and the summary; 1 when a case fails."""
    env = os.environ.get("BENCH_SELECT_CASES", "")
    ids = [int(x) for x in env.split(",") if x.strip()] or [c[0] for c in CASES]
    unknown = sorted(set(ids) - {c[0] for c in CASES})
    if unknown:
        print(f"error: unknown case(s) {unknown}; cases are 1..{len(CASES)}")
        return 2
    log = logging.getLogger("sysid")
    level = log.level
    log.setLevel(logging.ERROR)  # the selection's notes per case would drown the table
    print(f"{'case':>4} {'description':38s} {'chose p/f/n focus D pk':24s} {'truth':>6s} "
          f"{'oracle':>6s} {'gap':>6s} {'warn':>4s} {'wall':>6s}", flush=True)
    rows: list[dict] = []
    failed: list[int] = []
    t0 = time.perf_counter()
    try:
        for cid in ids:
            try:
                r = run_case(cid)
            except Exception as exc:  # report and go on with the others
                failed.append(cid)
                print(f"{cid:4d} {describe(spec(cid)):38s} FAILED: {exc!r:.200}", flush=True)
                continue
            rows.append(r)
            how = (f"{r['past']}/{r['future']}/{r['order']} {r['focus'][:4]}"
                   f"{' D' if r['D'] else ''}{' pk' if r['method'] == 'parsim-k' else ''}")
            mark = "*" if r["unranked"] else ""
            print(f"{cid:4d} {describe(r['spec']):38s} {how:24s} {r['truth']:6.2f} "
                  f"{r['oracle']:6.2f} {r['gap']:+6.2f} {len(r['warnings']):3d}{mark:1s} "
                  f"{r['wall']:5.1f}s", flush=True)
    finally:
        log.setLevel(level)
    print("(warn: the selection's warnings; * = the held-out data cannot rank the models; "
          "pk: PARSIM-K chosen beside IEM)")
    _summary(rows, failed, time.perf_counter() - t0)
    return 1 if failed else 0
