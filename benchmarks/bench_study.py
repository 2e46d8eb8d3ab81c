"""A tolerance study of 10,000 variants × 360 samples against one run of 3.6 million samples, in one process.

    python benchmarks/bench_study.py                    # 10,000 variants × 360 samples, the target's case
    python benchmarks/bench_study.py --variants 2000 --samples 360 --repeat 3 --workers 2

The study: the textbook four-bar (mechanisms/fourbar_textbook_example.toml) with its three moving links'
lengths toleranced ±0.05 mm (uniform) and the ground pivot O4 with σ = 0.03 mm (normal); outputs the
rocker's swing, its peak angular acceleration, the minimum transmission angle and the coupler joint's
peak acceleration; sensitivities at the nominal design (9 more variants). Every variant is solved over
the file's 0.5 s at ``samples`` samples. The baseline: ``vloop.solve`` of the nominal design over the
same 0.5 s at variants × samples samples (one run, its results kept in memory as vloop.solve does).

Times are the best of ``--repeat`` runs, BLAS pinned to one thread (threadpoolctl). Memory: the peak of
the memory numpy and Python allocate during each (tracemalloc, a separate pass so it does not slow the
timed runs). The target: the study in at most 3× the time of the baseline.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402

PARAMS = [
    {"name": "links.l2.length", "tolerance": {"dist": "uniform", "half_width": 0.05}},
    {"name": "links.l3.length", "tolerance": {"dist": "uniform", "half_width": 0.05}},
    {"name": "links.l4.length", "tolerance": {"dist": "uniform", "half_width": 0.05}},
    {"name": "joints.O4.x", "tolerance": {"dist": "normal", "sigma": 0.03}},
]
OUTPUTS = ["l4.theta.range", "l4.alpha.peak", "transmission_angle.min", "B.acceleration.peak"]


def best_of(fn, repeat: int) -> tuple[float, object]:
    best, out = math.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def peak_memory(fn) -> float:
    """Peak bytes allocated (tracemalloc) while ``fn`` runs, in MB."""
    tracemalloc.start()
    tracemalloc.reset_peak()
    fn()
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return peak / 2**20


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--variants", type=int, default=10_000)
    ap.add_argument("--samples", type=int, default=360)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--workers", type=int, default=None, help="also time the study on a local Dask cluster")
    args = ap.parse_args()
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    mech = vloop.load(ROOT / "mechanisms" / "fourbar_textbook_example.toml")
    times = np.linspace(0.0, 0.5, args.samples)
    long = np.linspace(0.0, 0.5, args.variants * args.samples)
    system = vloop.compile(mech)

    def study(**kw):
        return vloop.study(mech, PARAMS, OUTPUTS, times=times, samples=args.variants, seed=1, **kw)

    def nominal():
        return vloop.solve(system, long)

    t_study, res = best_of(study, args.repeat)
    t_nominal, big = best_of(nominal, args.repeat)
    rows = args.variants * args.samples
    print(f"textbook four-bar, BLAS on one thread; {args.variants:,} variants × {args.samples} samples")
    print(
        f"  study            {t_study:7.2f} s  ({rows / t_study / 1e6:.2f} M variant-samples/s; "
        f"{res.counts['completed']:,} completed, {res.counts['single_runs']} solved one by one)"
    )
    print(
        f"  one nominal run  {t_nominal:7.2f} s  "
        f"({len(big.t) / t_nominal / 1e6:.2f} M samples/s, {len(big.t):,} samples)"
    )
    print(f"  ratio study / nominal = {t_study / t_nominal:.2f}  (target ≤ 3)")
    del big
    m_study, m_nominal = peak_memory(study), peak_memory(nominal)
    print(f"  peak allocated: study {m_study:,.0f} MB, nominal run {m_nominal:,.0f} MB")
    s = res.summary
    for _, row in s.iterrows():
        print(
            f"  {row['output']:24s} nominal {row['nominal']:.6g}  σ linearized {row['linearized_sigma']:.4g}  "
            f"Monte-Carlo {row['mc_sigma']:.4g} ± {row['mc_sigma_error']:.2g}"
        )
    if args.workers:
        t_dask, there = best_of(lambda: study(workers=args.workers), 1)
        same = all(np.array_equal(res.table[c].to_numpy(), there.table[c].to_numpy(), equal_nan=True) for c in OUTPUTS)
        print(f"  on {args.workers} Dask workers: {t_dask:.2f} s (cluster start included); same numbers: {same}")


if __name__ == "__main__":
    main()
