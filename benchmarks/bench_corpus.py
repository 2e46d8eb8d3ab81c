"""Validation of a generated corpus: in this process against a local Dask cluster of 2 worker processes.

    python benchmarks/bench_corpus.py                      # 1,000 mechanisms × 4 engines
    python benchmarks/bench_corpus.py --n 200 --workers 2 4

Each mode runs in its own child process (so its peak memory is its own): the corpus (seed 2026) is
generated and written once, then ``validators.harness.run`` validates every mechanism with vloop, the
closed forms, Pinocchio and Exudyn (kinematic) — one task per mechanism × engine through
``vloop.runner``. Printed per mode: wall time of the validation, tasks per second, the speed-up over the
in-process run, the cluster's start-up time (separately), the CPU time of the main process (client,
scheduler and the comparisons, which all run there) and peak resident memory of the main process and
of the largest worker. The runs must give the same summary (numbers, not timings): checked here.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

ENGINES = ("vloop", "analytic", "pinocchio", "exudyn-kinematic")


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def _cpu_seconds() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def _worker_peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child(folder: Path, workers: int, out: Path) -> None:
    """One mode, in this (child) process: validate every file in ``folder``; write the figures to ``out``."""
    from validators import harness

    files = sorted(folder.glob("*.toml"))
    startup, worker_mb, address, cluster = 0.0, 0.0, None, None
    if workers:
        from distributed import Client, LocalCluster

        t0 = time.perf_counter()
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None)
        address = cluster.scheduler_address
        startup = time.perf_counter() - t0
    cpu0 = _cpu_seconds()
    t0 = time.perf_counter()
    v = harness.run(files, ENGINES, scheduler=address, timeout=600)
    seconds = time.perf_counter() - t0
    summary = harness.to_summary(v)
    if cluster is not None:
        with Client(address) as c:
            worker_mb = max(c.run(_worker_peak_mb).values())
        cluster.close()
    for m in summary["mechanisms"]:
        for r in m["runs"].values():
            for k in ("seconds", "task_seconds", "worker"):
                r.pop(k)
    for k in ("created", "seconds", "runner"):
        summary.pop(k)
    figures = {
        "workers": workers,
        "seconds": seconds,
        "startup": startup,
        "tasks": len(files) * len(ENGINES),
        "main_mb": _peak_mb(),
        "main_cpu": _cpu_seconds() - cpu0,
        "worker_mb": worker_mb,
        "passed": sum(m["passed"] for m in summary["mechanisms"]),
        "mechanisms": len(summary["mechanisms"]),
        "summary": summary,
    }
    out.write_text(json.dumps(figures))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1000, help="mechanisms (default 1000)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--workers", type=int, nargs="+", default=[2], help="cluster sizes to compare (default 2)")
    ap.add_argument("--child", nargs=3, metavar=("FOLDER", "WORKERS", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(Path(args.child[0]), int(args.child[1]), Path(args.child[2]))
        return
    from validators import corpus

    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "corpus"
        t0 = time.perf_counter()
        items, _ = corpus.generate(args.n, args.seed)
        corpus.write(items, folder, seed=args.seed)
        samples = sum(len(it.mechanism.times) for it in items)
        print(
            f"corpus: {args.n} mechanisms (seed {args.seed}, {samples} samples in all), generated in "
            f"{time.perf_counter() - t0:.1f} s; engines: {', '.join(ENGINES)}"
        )
        results = []
        for w in [0, *args.workers]:
            out = Path(tmp) / f"figures-{w}.json"
            subprocess.run([sys.executable, __file__, "--child", str(folder), str(w), str(out)], check=True)
            results.append(json.loads(out.read_text()))
    base = results[0]
    print(
        f"{'mode':>22s} {'validation':>11s} {'tasks/s':>8s} {'speed-up':>9s} {'start-up':>9s} "
        f"{'main CPU':>9s} {'main MB':>8s} {'worker MB':>10s}  passed"
    )
    for r in results:
        mode = "in-process" if not r["workers"] else f"LocalCluster {r['workers']} proc"
        same = "" if r["summary"] == base["summary"] else "  SUMMARY DIFFERS"
        print(
            f"{mode:>22s} {r['seconds']:10.1f}s {r['tasks'] / r['seconds']:8.1f} "
            f"{base['seconds'] / r['seconds']:8.2f}x {r['startup']:8.1f}s {r['main_cpu']:8.1f}s {r['main_mb']:8.0f} "
            f"{r['worker_mb']:10.0f}  {r['passed']}/{r['mechanisms']}{same}"
        )


if __name__ == "__main__":
    main()
