"""Speed of the eight-bar's full P/V/A history: vloop against two baselines, in one process.

    python benchmarks/bench_eightbar.py            # 48 and 4,800 steps
    python benchmarks/bench_eightbar.py --steps 48 480 4800 48000 --repeat 30

Baselines, run here in the same process so the ratios are meaningful on a noisy machine:
(a) the paper's method: scipy.optimize.fsolve per time step for the positions (Eq. 6),
    then per step for the velocities (Eq. 4) and accelerations (Eq. 5), warm-started
    with the previous step's solution as the paper does;
(b) the hand-derived closed form, vectorized in numpy (validators/analytic/eightbar.py).
vloop is timed on a compiled LoopSystem (compiling — graph, loops, assembly — is
a one-off per mechanism and is reported on its own line). Times are the best of
``--repeat`` runs (the minimum is the least noisy estimate of the cost).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import warnings
from pathlib import Path

# The matrix products here are tiny (thousands × a few); OpenBLAS's threads gain nothing on
# them and, when the other core is busy, make every product wait — run BLAS single-threaded.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from scipy.optimize import fsolve

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from validators.analytic import eightbar as analytic_eightbar  # noqa: E402

# The paper's Table 1 / Fig. 1 constants.
A_, B_, D_, M_, H_ = 3.0, 5.0, 6.15, 6.15, 8.0
OMEGA2, ALPHA2, THETA20 = 3.0, 0.0, np.pi / 2


def paper_fsolve(t: np.ndarray) -> dict[str, np.ndarray]:
    """The paper's algorithm: per-step fsolve on Eqs. 6, 4 and 5 (unknowns θ3, c, θ5, k, θ7, g)."""
    th2 = THETA20 + OMEGA2 * t + 0.5 * ALPHA2 * t * t
    w2 = OMEGA2 + ALPHA2 * t
    n = len(t)
    pos = np.zeros((n, 6))
    vel = np.zeros((n, 6))
    acc = np.zeros((n, 6))
    e = np.exp

    def position(x, k):
        th3, c, th5, kk, th7, g = x
        l1 = A_ * e(1j * th2[k]) + B_ * e(1j * th3) + c * e(1j * np.pi)
        l2 = D_ * e(1j * th5) + kk * e(1.5j * np.pi) + (H_ - c) * e(1j * np.pi)
        l3 = M_ * e(1j * th7) + g * e(0.5j * np.pi) + (H_ - c) * e(1j * np.pi)
        return [l1.real, l1.imag, l2.real, l2.imag, l3.real, l3.imag]

    guess = np.array([5.6397, 4.0, 0.8627, 4.6715, 5.4205, 4.6715])
    for k in range(n):
        guess = fsolve(position, guess, args=(k,))
        pos[k] = guess

    def velocity(x, k):
        th3, _, th5, _, th7, _ = pos[k]
        w3, cd, w5, kd, w7, gd = x
        l1 = 1j * A_ * w2[k] * e(1j * th2[k]) + 1j * B_ * w3 * e(1j * th3) + cd * e(1j * np.pi)
        l2 = 1j * D_ * w5 * e(1j * th5) + kd * e(1.5j * np.pi) - cd * e(1j * np.pi)
        l3 = 1j * M_ * w7 * e(1j * th7) + gd * e(0.5j * np.pi) - cd * e(1j * np.pi)
        return [l1.real, l1.imag, l2.real, l2.imag, l3.real, l3.imag]

    guess = np.zeros(6)
    for k in range(n):
        guess = fsolve(velocity, guess, args=(k,))
        vel[k] = guess

    def acceleration(x, k):
        th3, _, th5, _, th7, _ = pos[k]
        w3, _, w5, _, w7, _ = vel[k]
        a3, cdd, a5, kdd, a7, gdd = x
        l1 = (
            (1j * ALPHA2 - w2[k] ** 2) * A_ * e(1j * th2[k])
            + (1j * a3 - w3**2) * B_ * e(1j * th3)
            + cdd * e(1j * np.pi)
        )
        l2 = (1j * a5 - w5**2) * D_ * e(1j * th5) + kdd * e(1.5j * np.pi) - cdd * e(1j * np.pi)
        l3 = (1j * a7 - w7**2) * M_ * e(1j * th7) + gdd * e(0.5j * np.pi) - cdd * e(1j * np.pi)
        return [l1.real, l1.imag, l2.real, l2.imag, l3.real, l3.imag]

    guess = np.zeros(6)
    for k in range(n):
        guess = fsolve(acceleration, guess, args=(k,))
        acc[k] = guess
    return {"pos": pos, "vel": vel, "acc": acc}


def best_of(fn, repeat: int) -> float:
    fn()  # warm caches
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--steps", type=int, nargs="+", default=[48, 4800])
    p.add_argument("--repeat", type=int, default=20)
    p.add_argument("--fsolve-repeat", type=int, default=1, help="runs of the (slow) fsolve baseline")
    args = p.parse_args(argv)

    # fsolve with MATLAB-like defaults, as in the paper; it warns on slow progress at some steps
    warnings.filterwarnings("ignore", category=RuntimeWarning, module="scipy")
    mech = vloop.load(ROOT / "mechanisms" / "eightbar.toml")
    t_compile = best_of(lambda: vloop.compile(mech), max(3, args.repeat // 4))
    system = vloop.compile(mech)
    print(f"vloop compile (graph, loops, t = 0 assembly, blocks): {t_compile * 1e3:.2f} ms, once per mechanism\n")
    head = f"{'steps':>7} {'method':<34} {'time':>11} {'steps/s':>12} {'vs closed form':>15} {'vloop faster':>13}"
    print(head)
    print("-" * len(head))
    for n in args.steps:
        t = np.linspace(0.0, 2.35, n + 1)[:n] if n != 48 else mech.times
        t_v = best_of(lambda t=t: vloop.solve(system, t), args.repeat)
        t_n = best_of(lambda t=t: vloop.solve(system, t, method="newton"), max(1, args.repeat // 10))
        t_c = best_of(lambda t=t: analytic_eightbar.solve(mech, t), args.repeat)
        t_f = best_of(lambda t=t: paper_fsolve(t), args.fsolve_repeat) if n <= 10_000 else float("nan")
        ref_f = paper_fsolve(t) if n <= 10_000 else None
        # same answers (a benchmark of wrong results is worthless): the closed form to 1e-9 of scale
        res, ref = vloop.solve(system, t), analytic_eightbar.solve(mech, t)
        worst = max(
            np.max(np.abs(res[c] - ref[c])) / max(np.max(np.abs(ref[c])), 1e-300)
            for c in ("l3.theta", "l5.omega", "l7.alpha", "l4.a", "l6.v", "l8.s")
        )
        assert worst < 1e-9, f"vloop and the closed form disagree ({worst:.2g})"
        if ref_f is not None:  # how accurate the paper's method is, for the record
            err_f = np.max(np.abs(ref_f["acc"][:, 0] - ref["l3.alpha"])) / np.max(np.abs(ref["l3.alpha"]))
            print(f"{n:>7} accuracy of (a) on α3 vs the closed form: {err_f:.1e} of peak; vloop: {worst:.1e}")
        for label, tt in (
            ("vloop (closed-form blocks)", t_v),
            ("vloop (Newton, Taylor predictor)", t_n),
            ("(b) closed form, numpy", t_c),
            ("(a) paper: fsolve per step", t_f),
        ):
            print(f"{n:>7} {label:<34} {tt * 1e3:>9.3f}ms {n / tt:>12,.0f} {tt / t_c:>14.2f}x {tt / t_v:>12.1f}x")
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
