"""The main process's memory of ``vloop validate --corpus N`` at any N, without running N × 5 engines.

    python benchmarks/bench_nightly_memory.py --source validation/comparisons --n 1000 10000

The engines run in the workers; what the main process holds grows, if at all, with the corpus (the corpus drawn and
written, the tasks' bookkeeping, summary.json, the comparison table and the pages streamed from the dataset). This
script measures every one of those stages but the engines: for each N it fills ``OUT/.vloop-run`` (the run in
progress, as an interrupted run leaves it) with N task files copied in turn from a real run's dataset (``--source``:
a ``comparisons/`` folder written by ``vloop validate``; its entries are real, repeated), and runs
``vloop validate --corpus N --seed S --engines E --workers 1 --resume`` under benchmarks/rss_sample.py: the corpus of
N is generated and written, the local cluster started, every task found done, and the summary, the table and
corpus.html streamed from the N files. Printed per N: the main process's peak RSS, its wall time, and the ratio of
the peaks. The task phase's own growth is measured by a real run (rss_sample.py around ``vloop validate``).
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def prepare(source: Path, out: Path, n: int, seed: int, engines: list[str]) -> None:
    """OUT/.vloop-run as a run of N (--corpus N --seed S --engines E) left it with every task done."""
    files = sorted(source.glob("family=*/[0-9]*.parquet"))
    if not files:
        raise SystemExit(f"{source}: no task files (family=*/NNNNNN.parquet)")
    work = out / ".vloop-run"
    (work / "comparisons").mkdir(parents=True)
    corpus = {"n": n, "seed": seed, "start": 0, "families": None, "limit_fraction": 0.1}
    (work / "run.json").write_text(json.dumps({"engines": engines, "files": [], "corpus": corpus}, indent=1))
    for k in range(n):
        src = files[k % len(files)]
        dst = work / "comparisons" / src.parent.name / f"{k:06d}.parquet"
        dst.parent.mkdir(exist_ok=True)
        shutil.copyfile(src, dst)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--source", type=Path, required=True, help="a real run's comparisons/ dataset")
    ap.add_argument("--n", type=int, nargs="+", default=[1000, 10000])
    ap.add_argument("--seed", type=int, default=2026)
    ap.add_argument("--engines", default="vloop,analytic,pinocchio,exudyn-kinematic,exudyn-dynamic")
    args = ap.parse_args()
    engines = args.engines.split(",")
    peaks = {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.n:
            out = Path(tmp) / f"run-{n}"
            prepare(args.source, out, n, args.seed, engines)
            figures = Path(tmp) / f"rss-{n}.json"
            cmd = [sys.executable, "-m", "vloop.cli", "validate", "--corpus", str(n), "--seed", str(args.seed)]
            cmd += ["--engines", args.engines, "--workers", "1", "--resume", "--minimize-tries", "0", "--out", str(out)]
            subprocess.run(
                [sys.executable, str(ROOT / "benchmarks" / "rss_sample.py"), "--json", str(figures), "--", *cmd],
                check=False, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            )  # fmt: skip
            fig = json.loads(figures.read_text())
            peaks[n] = fig["main_peak_mb"]
            summary = json.loads((out / "summary.json").read_text())
            print(
                f"N = {n:6d}: main process peak RSS {fig['main_peak_mb']:6.0f} MB, {fig['seconds']:6.0f} s "
                f"(exit {fig['exit']}; summary {summary['counts']['mechanisms']} mechanisms, "
                f"load average {fig['load_average']['mean']:.1f})",
                flush=True,
            )
    ns = sorted(peaks)
    if len(ns) > 1:
        print(f"peak at {ns[-1]} / peak at {ns[0]}: {peaks[ns[-1]] / peaks[ns[0]]:.2f}")


if __name__ == "__main__":
    main()
