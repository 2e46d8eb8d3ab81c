"""Path synthesis speed, in one process: the batched evaluation's throughput, and vloop against pylinkage.

    python benchmarks/bench_synthesis.py                       # both parts, seeds 0..4
    python benchmarks/bench_synthesis.py --seeds 0 1 2 --skip-pylinkage

1. **Throughput.** One generation's worth of work: a population of 1,000 random four-bars (coordinates drawn in a
   box of ±1.5 around the origin, either input direction) × 360 input angles of a full turn, through
   ``vloop.synthesis._evaluate.evaluate`` — the one call the search makes per generation. Best of ``--repeat``
   runs after one untimed run; candidate-samples per second = 1,000 × 360 / time. Also the same population with
   the batch's default fallback (``doubtful="single"``: every variant the batch is not sure of solved again one
   by one), once, to show what the synthesis's ``doubtful="fail"`` saves. Target: ≥ 1 M candidate-samples/s
   (1,000 × 360 in ≤ 0.4 s on a quiet machine).
2. **Against pylinkage 1.3.0** (``pip install "vloop[bench]"``) on the same five-point paths: time to a
   four-bar whose coupler passes every point within 1 % of the points' size (bounding-box diagonal, pylinkage's
   own measure). vloop: ``vloop.synthesis.path(points, count=1, seed=s, linkage="fourbar")`` (it stops at the
   first polished candidate within the tolerance; its candidate must be free of defects and is re-solved by
   vloop; errors from that re-solve). pylinkage: ``path_generation(points, max_solutions=k)`` for k = 1, 2, 4,
   … until one of its solutions is within 1 % by ``verify_path_generation`` (its own check, one turn of its
   own simulation), timing that call; pylinkage's search has no seed (it is deterministic). Paths: five points
   on the coupler curve of a crank-rocker (a solution exists), and pylinkage's docstring example with a fifth
   point. The ratios: vloop's median time over the seeds, and its slowest seed, against pylinkage's (the smaller
   of a run before vloop's and one after); target ≤ 0.5 for both.

The machine is shared: the load average is printed with the figures, and only ratios measured in this one
process mean anything.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
import vloop.synthesis as syn  # noqa: E402
from vloop.core import batch  # noqa: E402
from vloop.synthesis._evaluate import _model, evaluate  # noqa: E402
from vloop.synthesis.linkages import FOURBAR  # noqa: E402

PATHS = {
    "coupler curve": [
        (0.41934593890973426, 1.0513270942571156),
        (-0.10446537637103137, 0.8670381554372484),
        (-0.32097851881852996, 0.3438328126846981),
        (-0.08455135714254489, 0.11120686613006159),
        (0.3738437688535382, 0.6051205522614385),
    ],  # P of O2 (0, 0), A (0.3, 0.4), B (1.2, 1.1), O4 (1.3, 0), P (0.5, 1.0) at crank angles 0.3 + 2πk/5
    "pylinkage example + 1": [(0.0, 1.0), (1.0, 2.0), (2.0, 1.5), (3.0, 0.0), (1.5, -0.5)],
}


def best_of(fn, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def throughput(population: int, samples: int, repeat: int) -> None:
    rng = np.random.default_rng(0)
    coords = rng.uniform(-1.5, 1.5, (population, 2 * len(FOURBAR.coordinates)))
    omega = np.where(rng.uniform(size=population) < 0.5, -1.0, 1.0)
    times = np.arange(samples) * (2 * math.pi / samples)

    def run():
        return evaluate(FOURBAR, coords, omega, times, points=("P",))

    ev = run()
    t = best_of(run, repeat)
    rate = population * samples / t
    print(f"evaluate: {population:,} four-bars × {samples} input angles in {t:.3f} s = {rate / 1e6:.2f} M candidate-"
          f"samples/s ({int(ev.completed.sum())} complete a turn); target ≥ 1 M/s, ≤ 0.4 s")  # fmt: skip
    model = _model(FOURBAR, (1.0,))
    values = np.concatenate([coords, omega[:, None]], 1)
    from vloop.synthesis.linkages import side

    z = coords[:, 0::2] + 1j * coords[:, 1::2]
    keep = side({k: z[:, i] for i, k in enumerate(FOURBAR.coordinates)}, FOURBAR.dyads[0]) > 0
    grid = batch.make_grid(model, model.designs(values[keep]), times)
    t_fail = best_of(lambda: batch.solve(model, values[keep], grid, ["P.x", "P.y"], doubtful="fail"), 1)
    t0 = time.perf_counter()
    out = batch.solve(model, values[keep], grid, ["P.x", "P.y"])
    t_single = time.perf_counter() - t0
    singles = sum(s == "single" for s in out.solver)
    print(f"  one branch's {int(keep.sum())} rows: doubtful='fail' {t_fail:.3f} s, the default fallback "
          f"{t_single:.2f} s ({singles} rows solved again one by one): {t_single / t_fail:.0f}× longer")  # fmt: skip


def vloop_time(points, seed: int) -> tuple[float, float, bool]:
    t0 = time.perf_counter()
    res = syn.path(points, count=1, seed=seed, linkage="fourbar", tolerance=0.01)
    dt = time.perf_counter() - t0
    c = res.best or (res[0] if len(res) else None)
    return dt, (c.error if c else math.inf), bool(c and c.solution)


def pylinkage_time(points) -> tuple[float, float, int]:
    from pylinkage.synthesis import path_generation
    from pylinkage.synthesis.path_generation import verify_path_generation

    xs, ys = [p[0] for p in points], [p[1] for p in points]
    size = math.hypot(max(xs) - min(xs), max(ys) - min(ys))
    k, dt, best = 1, math.inf, math.inf
    while k <= 64:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            t0 = time.perf_counter()
            res = path_generation(list(points), max_solutions=k)
            dt = time.perf_counter() - t0
            errs = [max(verify_path_generation(s, list(points))[1]) / size for s in res.solutions]
        best = min(errs, default=math.inf)
        if best <= 0.01 or len(res.solutions) < k:
            break
        k *= 2
    return dt, best, k


def compare(seeds: list[int]) -> bool:
    """Each path: vloop's time per seed against pylinkage's (the smaller of a run before and one after vloop's, so
    a change of load between them counts against vloop). Returns whether every ratio met the target."""
    import pylinkage

    print(f"against pylinkage {pylinkage.__version__}: time to a four-bar within 1 % of the points' size")
    met = True
    for name, points in PATHS.items():
        before = pylinkage_time(points)
        runs = [vloop_time(points, s) for s in seeds]
        after = pylinkage_time(points)
        t_p, e_p, k = min(before, after)
        t_v = float(np.median([r[0] for r in runs]))
        ok = all(r[2] and r[1] <= 0.01 for r in runs)
        verdict = "all free of defects" if ok else "NOT all solutions"
        times = ", ".join(f"{r[0]:.2f}" for r in runs)
        print(f"  {name}: vloop {times} s (seeds {seeds}; median {t_v:.2f} s; "
              f"largest error {max(r[1] for r in runs):.1e}; {verdict})")  # fmt: skip
        status = f"error {e_p:.2%}" if math.isfinite(e_p) else "no solution"
        worst = max(r[0] for r in runs) / t_p
        print(f"    pylinkage {t_p:.2f} s (before {before[0]:.2f} s, after {after[0]:.2f} s; max_solutions={k}, "
              f"{status}); vloop/pylinkage: median {t_v / t_p:.2f}, slowest {worst:.2f} (target ≤ 0.5)")  # fmt: skip
        met &= ok and worst <= 0.5
    return met


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--population", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=360)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    ap.add_argument("--skip-pylinkage", action="store_true")
    args = ap.parse_args()
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:
        pass
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"load average {load} on {os.cpu_count()} cores; vloop {vloop.__version__}")
    throughput(args.population, args.samples, args.repeat)
    if not args.skip_pylinkage:
        print("every ratio within the target" if compare(args.seeds) else "a ratio or a candidate MISSED the target")
    print(f"load average afterwards {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
