"""Where the Newton path's time goes, against the closed-form (dyad) path in the same process.

    python benchmarks/bench_newton_floor.py                         # eight-bar, 4,800 steps
    python benchmarks/bench_newton_floor.py --only eightbar jansen_pair --steps 4800 48000 --repeat 200

For each mechanism, rounds in which ``solve(system)`` (auto) and ``solve(system, method="newton")`` take
turns (bench_speed.rounds_of_each: each called once untimed first). Inside the Newton run two stages are timed
by wrapping the functions of ``vloop.core.newton`` that do them:

* the coarse continuation (``_coarse_pass``): rows ~15° of input travel apart solved one window after the
  other from Taylor predictors, each checked for the branch (this is what keeps the path on its assembly
  branch; its cost does not grow with the run);
* the exact condition numbers (``_condition_near``): where the cheap bound reaches the flag level, the
  exact 2-norm value, so flags and refusals follow the SVD rule exactly.

Prints, per mechanism and size, the newton/auto ratio and the ratio of what remains with both stages taken
out — the per-row passes (prediction, Newton and chord steps, the factor, rates, results). That remainder
is the floor of this design in numpy: the Newton path cannot come closer to the dyad path than it without
giving up the branch tracking or the exact flags. Ratios are medians (and 10th percentiles) over rounds,
each round's newton time over the same round's auto time (auto's own Newton blocks, as the output-driven
six-bar's, timed whole). BLAS runs one thread.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench_speed import rounds_of_each, worst_relative  # noqa: E402  (this script's folder is on sys.path)

import vloop  # noqa: E402
from vloop.core import linalg, newton  # noqa: E402

STAGES = {"coarse": (newton, "_coarse_pass"), "exact_cond": (linalg, "_condition_near")}


def timed(fn: Callable, spent: dict[str, float], label: str) -> Callable:
    """``fn`` adding its wall time to spent[label] at every call."""

    def wrapper(*args: object, **kwargs: object) -> object:
        t0 = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            spent[label] += time.perf_counter() - t0

    return wrapper


def rounds(name: str, steps: int, repeat: int, spent: dict[str, float]) -> tuple[np.ndarray, float]:
    """(repeat, 4): auto, newton, coarse, exact-cond seconds per round (bench_speed's turns: each function called
    twice, the second call timed); and newton's largest difference from auto (relative to each column's peak)."""
    mech = vloop.load(ROOT / "mechanisms" / f"{name}.toml")
    system = vloop.compile(mech)
    t = np.linspace(mech.times[0], mech.times[-1], steps)
    gap = worst_relative(vloop.solve(system, t, method="newton"), vloop.solve(system, t))
    stages: list[tuple[float, float]] = []  # per newton call: its coarse and exact-cond seconds

    def newton() -> None:
        spent.update(dict.fromkeys(spent, 0.0))
        vloop.solve(system, t, method="newton")
        stages.append((spent["coarse"], spent["exact_cond"]))

    times = rounds_of_each({"auto": lambda: vloop.solve(system, t), "newton": newton}, repeat)
    return np.column_stack([times["auto"], times["newton"], np.array(stages[1::2])]), gap


def report(name: str, steps: int, R: np.ndarray, gap: float) -> str:
    auto, newton, coarse, exact = R.T
    ratio, floor = newton / auto, (newton - coarse - exact) / auto
    return (
        f"{name} {steps:,} steps (newton vs auto {gap:.1e} of peak): auto {auto.min() * 1e3:.2f} ms, newton "
        f"{newton.min() * 1e3:.2f} ms (best); coarse continuation {np.median(coarse) * 1e3:.2f} ms, exact condition "
        f"numbers {np.median(exact) * 1e3:.2f} ms (medians)\n"
        f"  newton / auto: median {np.median(ratio):.2f}x (p10 {np.percentile(ratio, 10):.2f}x); "
        f"without both stages: median {np.median(floor):.2f}x (p10 {np.percentile(floor, 10):.2f}x)"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", default=["eightbar"])
    ap.add_argument("--steps", nargs="+", type=int, default=[4800])
    ap.add_argument("--repeat", type=int, default=200)
    args = ap.parse_args(argv)
    spent = dict.fromkeys(STAGES, 0.0)
    for label, (module, fname) in STAGES.items():
        setattr(module, fname, timed(getattr(module, fname), spent, label))
    for name in args.only:
        for steps in args.steps:
            print(report(name, steps, *rounds(name, steps, args.repeat, spent)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
