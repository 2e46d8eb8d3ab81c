"""Validation of a generated corpus at scale: throughput per worker, memory per worker, which engine dominates.

    python benchmarks/bench_corpus.py                                   # 300 mechanisms × 5 engines, 2 workers
    python benchmarks/bench_corpus.py --n 200 --workers 0 2             # also in this process (same summary?)
    python benchmarks/bench_corpus.py --engines vloop,analytic,pinocchio,exudyn-kinematic

Each mode runs in its own child process (so its peak memory is its own): the corpus (seed 2026) is generated and
written once, then ``validators.harness.run`` validates every mechanism with the engines — one task per mechanism
(its engines, comparisons and verdict) through ``vloop.runner`` (0 workers: in this process; N: a local Dask
cluster of N single-threaded worker processes). Printed per mode: wall time of the validation, the cluster's
start-up (separately), mechanisms per minute in all and per worker, the CPU time of the main process (client and
scheduler), peak resident memory of the main process and of the largest worker, and the machine's load average
while it ran.

Then, per engine, where the time goes: its CPU seconds summed over the tasks (``EngineRun.cpu_seconds``, measured
in the process that ran it, so a machine shared with other work does not inflate it), its share, its milliseconds
per mechanism and the mechanisms per minute one worker gets through with that engine alone; and the extrapolation
to ``--target`` mechanisms (10,000): the engines' CPU per mechanism × target / workers, plus the main process's CPU
per mechanism × target (it runs beside the workers but needs its own core time), which is what the run takes on a
machine with a core free per worker; and, for comparison, the wall time measured here scaled to the target
(inflated by whatever else the machine is doing). The runs must give the same summary (numbers, not timings):
checked here.
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

ENGINES = ("vloop", "analytic", "pinocchio", "exudyn-kinematic", "exudyn-dynamic")
TIMING = ("seconds", "task_seconds", "cpu_seconds", "worker")


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def _cpu_seconds() -> float:
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime


def child(folder: Path, workers: int, engines: tuple[str, ...], out: Path) -> None:
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
    load0 = os.getloadavg()[0]
    cpu0 = _cpu_seconds()
    t0 = time.perf_counter()
    v = harness.run(files, engines, scheduler=address, timeout=600)
    seconds = time.perf_counter() - t0
    load1 = os.getloadavg()[0]
    summary = harness.to_summary(v)
    if cluster is not None:
        with Client(address) as c:
            worker_mb = max(c.run(_peak_mb).values())
        cluster.close()
    per_engine = {e: 0.0 for e in engines}
    for m in summary["mechanisms"]:
        for name, r in m["runs"].items():
            per_engine[name] += r["cpu_seconds"]
            for k in TIMING:
                r.pop(k)
    for k in ("created", "seconds", "runner"):
        summary.pop(k)
    figures = {
        "workers": workers,
        "seconds": seconds,
        "startup": startup,
        "load": [load0, load1],
        "main_mb": _peak_mb(),
        "main_cpu": _cpu_seconds() - cpu0,
        "worker_mb": worker_mb,
        "engine_cpu": per_engine,
        "passed": sum(m["passed"] for m in summary["mechanisms"]),
        "mechanisms": len(summary["mechanisms"]),
        "verdicts": summary["verdicts"]["mechanisms"],
        "summary": summary,
    }
    out.write_text(json.dumps(figures))


def report(results: list[dict], engines: tuple[str, ...], target: int) -> None:
    """The table of modes, then where the time goes and the extrapolation to ``target`` mechanisms."""
    base = results[0]
    print(
        f"{'mode':>22s} {'validation':>11s} {'mech/min':>9s} {'/worker':>8s} {'start-up':>9s} {'main CPU':>9s} "
        f"{'main MB':>8s} {'worker MB':>10s} {'load avg':>10s}  passed (verdicts)"
    )
    for r in results:
        mode = "in-process" if not r["workers"] else f"LocalCluster {r['workers']} proc"
        per_min = 60.0 * r["mechanisms"] / r["seconds"]
        same = "" if r["summary"] == base["summary"] else "  SUMMARY DIFFERS"
        print(
            f"{mode:>22s} {r['seconds']:10.1f}s {per_min:9.1f} {per_min / max(r['workers'], 1):8.1f} "
            f"{r['startup']:8.1f}s {r['main_cpu']:8.1f}s {r['main_mb']:8.0f} {r['worker_mb']:10.0f} "
            f"{r['load'][0]:4.1f}-{r['load'][1]:4.1f}  {r['passed']}/{r['mechanisms']} {r['verdicts']}{same}"
        )
    for r in results:
        n, workers = r["mechanisms"], max(r["workers"], 1)
        total = sum(r["engine_cpu"].values())
        print(f"\nwhere the time goes ({'in-process' if not r['workers'] else f'{workers} workers'}), engine CPU:")
        for e in sorted(engines, key=lambda e: -r["engine_cpu"][e]):
            cpu = r["engine_cpu"][e]
            rate = 60.0 * n / cpu if cpu > 0 else float("inf")
            print(
                f"  {e:18s} {cpu:8.1f} s  {100 * cpu / max(total, 1e-9):5.1f} %  {1000 * cpu / n:7.1f} ms/mechanism"
                f"  {rate:8.0f} mechanisms/minute/worker"
            )
        per_mech = total / n
        compute = target * per_mech / workers / 60
        main = target * r["main_cpu"] / n / 60
        wall = target * r["seconds"] / n / 60
        print(
            f"  {target} mechanisms: engines {per_mech:.3f} CPU-s/mechanism -> {compute:.1f} min on {workers} "
            f"worker(s), main process {main:.1f} CPU-min beside them; measured wall time scaled: {wall:.1f} min "
            f"(load average {r['load'][0]:.1f}-{r['load'][1]:.1f} on {os.cpu_count()} cores)"
        )
        print(f"  throughput at full cores: {60 / per_mech:.0f} mechanisms/minute/worker")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=300, help="mechanisms (default 300)")
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--workers", type=int, nargs="+", default=[2], help="modes: 0 = in process, N = N workers")
    ap.add_argument("--engines", default=",".join(ENGINES), help="comma-separated (default: all five)")
    ap.add_argument("--target", type=int, default=10_000, help="corpus size to extrapolate to (default 10000)")
    ap.add_argument("--child", nargs=4, metavar=("FOLDER", "WORKERS", "ENGINES", "OUT"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(Path(args.child[0]), int(args.child[1]), tuple(args.child[2].split(",")), Path(args.child[3]))
        return
    from validators import corpus

    engines = tuple(e.strip() for e in args.engines.split(",") if e.strip())
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "corpus"
        t0 = time.perf_counter()
        items, _ = corpus.generate(args.n, args.seed)
        corpus.write(items, folder, seed=args.seed)
        samples = sum(len(it.mechanism.times) for it in items)
        print(
            f"corpus: {args.n} mechanisms (seed {args.seed}, {samples} samples in all), generated in "
            f"{time.perf_counter() - t0:.1f} s; engines: {', '.join(engines)}"
        )
        results = []
        for w in args.workers:
            out = Path(tmp) / f"figures-{w}.json"
            cmd = [sys.executable, __file__, "--child", str(folder), str(w), ",".join(engines), str(out)]
            subprocess.run(cmd, check=True)
            results.append(json.loads(out.read_text()))
    report(results, engines, args.target)


if __name__ == "__main__":
    main()
