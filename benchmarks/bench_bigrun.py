"""Time and peak memory of a long `vloop run`, streamed to disk: the textbook four-bar at constant speed.

    python benchmarks/bench_bigrun.py                          # 1, 4 and 20 million samples to Parquet
    python benchmarks/bench_bigrun.py --samples 2e6 --format csv npz

Each run is a real `vloop` process (the peak resident memory is the child's ``ru_maxrss``); the output
goes to a temporary folder that is removed afterwards. Samples per second should stay flat with the
run's length and the peak memory bounded (chunks of 16,384 samples; only the time grid grows, 8 bytes
per sample).
"""

from __future__ import annotations

import argparse
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def four_bar(folder: Path, samples: int) -> Path:
    """The textbook four-bar turning at a constant 25 rad/s, ``samples`` samples 1e-4 s apart."""
    text = (ROOT / "mechanisms" / "fourbar_textbook_example.toml").read_text(encoding="utf-8")
    head = text.split("[time]")[0].replace("alpha = 15.0", "alpha = 0.0")
    path = folder / "fourbar.toml"
    path.write_text(head + f"[time]\nstart = 0.0\nstop = {(samples - 1) * 1e-4!r}\nstep = 0.0001\n", encoding="utf-8")
    return path


def run(samples: int, fmt: str) -> tuple[float, float, int]:
    """(seconds, peak RSS in MB, bytes written) of one streamed run."""
    exe = Path(sys.executable).with_name("vloop")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = four_bar(folder, samples)
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        t0 = time.perf_counter()
        proc = subprocess.run(
            [str(exe), "run", str(path), "--out", str(folder / "out"), "--format", fmt],
            capture_output=True,
            text=True,
        )
        seconds = time.perf_counter() - t0
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        if proc.returncode != 0:
            raise SystemExit(proc.stderr)
        size = sum(p.stat().st_size for p in (folder / "out").iterdir())
    if peak <= before:  # ru_maxrss is the largest child so far: a smaller run after a larger one reads low
        peak = float("nan")
    return seconds, peak / 1024.0, size


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--samples", type=float, nargs="+", default=[1e6, 4e6, 2e7])
    p.add_argument("--format", nargs="+", default=["parquet"], choices=["csv", "parquet", "npz"])
    args = p.parse_args(argv)
    print(f"{'samples':>12} {'format':>8} {'time [s]':>9} {'samples/s':>11} {'peak RSS [MB]':>14} {'files [MB]':>11}")
    for fmt in args.format:
        for n in sorted(int(s) for s in args.samples):
            seconds, peak, size = run(n, fmt)
            print(
                f"{n:>12,} {fmt:>8} {seconds:9.1f} {n / seconds:11,.0f} {peak:14.0f} {size / 2**20:11.0f}", flush=True
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
