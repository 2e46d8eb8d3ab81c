"""Cost of the teaching quantities against the solve they read, in one process.

    python benchmarks/bench_teaching.py                     # Jansen pair and eight-bar, 2,001 and 20,001 samples
    python benchmarks/bench_teaching.py --samples 201 200001 --repeat 3

For each mechanism and sample count: the solve (vloop.solve on a compiled LoopSystem, the baseline),
Kennedy's construction, the velocity-field construction, every extras column (vloop.teaching.extras:
both constructions merged, transmission angles, velocity ratios) and the cycle analysis
(vloop.teaching.cycle: dead centres, strokes, time ratios; independent of the run's samples), as
best-of-``--repeat`` seconds and as ratios to the solve; and the peak memory the extras add
(tracemalloc), per sample.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tracemalloc
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from vloop import teaching  # noqa: E402


def best(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, nargs="+", default=[2001, 20001])
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--mechanisms", nargs="+", default=["jansen_pair", "eightbar"])
    args = ap.parse_args()
    print(f"{'mechanism':14s} {'samples':>8s} {'solve s':>8s} {'kennedy':>9s} {'velocity':>9s} {'extras':>9s} "
          f"{'cycle s':>8s} {'extras B/sample':>16s}")  # fmt: skip
    for stem in args.mechanisms:
        mech = vloop.load(ROOT / "mechanisms" / f"{stem}.toml")
        system = vloop.compile(mech)
        t_cycle = best(lambda m=mech: teaching.cycle(m), 1)
        for n in args.samples:
            t = np.linspace(mech.times[0], mech.times[-1], n)
            res = vloop.solve(system, times=t)
            t_solve = best(lambda: vloop.solve(system, times=t), args.repeat)  # noqa: B023
            t_ken = best(lambda: teaching.kennedy_centres(mech, res), args.repeat)  # noqa: B023
            t_vel = best(lambda: teaching.velocity_centres(mech, res), args.repeat)  # noqa: B023
            t_ext = best(lambda: teaching.extras(mech, res, system=system), args.repeat)  # noqa: B023
            tracemalloc.start()
            teaching.extras(mech, res, system=system)
            peak = tracemalloc.get_traced_memory()[1]
            tracemalloc.stop()
            print(
                f"{stem:14s} {n:8d} {t_solve:8.3f} {t_ken / t_solve:8.2f}x {t_vel / t_solve:8.2f}x "
                f"{t_ext / t_solve:8.2f}x {t_cycle:8.2f} {peak / n:16.0f}"
            )


if __name__ == "__main__":
    main()
