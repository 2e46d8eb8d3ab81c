"""Cost of the kinetostatics against the kinematics of the same run, in one process.

    python benchmarks/bench_forces.py                 # the eight-bar with masses, 4,800 samples
    python benchmarks/bench_forces.py --steps 48 4800 48000 --repeat 30

For each sample count: vloop.solve on the compiled LoopSystem (positions, velocities, accelerations)
and vloop.forces.solve_forces on the compiled ForceModel (driver torque, 21 reactions, shaking
force) over the same Result; best of ``--repeat`` interleaved runs each (the minimum is the least
noisy estimate). Prints both times, their ratio (the target: forces ≤ 2× kinematics at 4,800
samples), the one-off compile times, and the peak memory of one forces run (tracemalloc).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import tracemalloc
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # tiny products: BLAS threads only wait (see bench_eightbar)
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from vloop.forces import compile_forces, solve_forces  # noqa: E402


def best(fns, repeat: int) -> list[float]:
    """Best time of each function, the runs interleaved so a busy machine slows them alike."""
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(repeat):
        for k, fn in enumerate(fns):
            t0 = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t0)
    return [min(t) for t in times]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--file", default=str(ROOT / "mechanisms" / "eightbar_dynamics.toml"))
    ap.add_argument("--steps", type=int, nargs="+", default=[48, 4800])
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args()
    mech = vloop.load(args.file)
    t0 = time.perf_counter()
    system = vloop.compile(mech)
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    model = compile_forces(mech)
    t_fcompile = time.perf_counter() - t0
    sizes = sorted({len(rows) for rows, _ in model.blocks}) if model.blocks else ["least squares"]
    print(f"{mech.name}: {len(model.unknowns)} unknowns, diagonal blocks of size {sizes}")
    print(f"compile: kinematics {t_compile * 1e3:.1f} ms, forces {t_fcompile * 1e3:.1f} ms (one-off per mechanism)")
    print(f"{'samples':>8s} {'kinematics':>12s} {'forces':>12s} {'ratio':>7s} {'forces peak memory':>20s}")
    worst = 0.0
    for n in args.steps:
        times = np.linspace(mech.times[0], mech.times[-1], n)
        res = vloop.solve(system, times)
        solve_forces(mech, res, model=model)  # warm
        t_kin, t_frc = best(
            [lambda times=times: vloop.solve(system, times), lambda res=res: solve_forces(mech, res, model=model)],
            args.repeat,
        )
        tracemalloc.start()
        solve_forces(mech, res, model=model)
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        ratio = t_frc / t_kin
        if n == 4800:
            worst = ratio
        print(f"{n:8d} {t_kin * 1e3:10.2f} ms {t_frc * 1e3:10.2f} ms {ratio:7.2f} {peak / 1e6:17.1f} MB")
    if worst:
        print(f"forces / kinematics at 4,800 samples: {worst:.2f} (target <= 2)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
