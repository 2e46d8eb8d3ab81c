"""Peak resident memory of a command's main process (and of its largest child), sampled from /proc while it runs.

    python benchmarks/rss_sample.py -- python -m vloop.cli validate --corpus 1000 --seed 2026 --workers 1 --out v
    python benchmarks/rss_sample.py --json rss.json --every 0.1 -- vloop validate --corpus 10000 ...

The command runs as a child of this script; every ``--every`` seconds the script reads VmRSS of that process (the
"main process": for ``vloop validate`` the client, the local scheduler and the summary's streaming) and of each of
its descendants (the Dask workers). Printed at the end: the command's exit code, wall time, the main process's peak
RSS and its RSS at the end, the largest descendant's peak, and the load average over the run (the machine may be
shared: the memory figures do not depend on it, the time does). ``ru_maxrss`` of the child is printed too (the
kernel's own peak, exact between samples). Linux only.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import time
from pathlib import Path


def rss_mb(pid: int) -> float:
    """VmRSS of ``pid`` in MB (0 if it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return 0.0


def descendants(pid: int) -> list[int]:
    """Every process below ``pid`` (from /proc/*/stat's parent ids)."""
    parent: dict[int, int] = {}
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                stat = (d / "stat").read_text()
                parent[int(d.name)] = int(stat[stat.rindex(")") + 2 :].split()[1])
            except (OSError, ValueError):
                continue
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        kids = [c for c, pp in parent.items() if pp == p]
        out += kids
        todo += kids
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--every", type=float, default=0.2, help="seconds between samples (0.2)")
    ap.add_argument("--json", type=Path, help="also write the figures (and the RSS trace) here")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- COMMAND ...")
    args = ap.parse_args()
    cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not cmd:
        ap.error("give the command after --")
    t0 = time.perf_counter()
    load0 = os.getloadavg()
    proc = subprocess.Popen(cmd)
    trace, peak_main, peak_child, loads = [], 0.0, 0.0, [load0[0]]
    k = 0
    while proc.poll() is None:
        main_mb = rss_mb(proc.pid)
        kids = [rss_mb(c) for c in descendants(proc.pid)] if k % 10 == 0 else []
        peak_main = max(peak_main, main_mb)
        peak_child = max([peak_child, *kids])
        trace.append((round(time.perf_counter() - t0, 2), round(main_mb, 1)))
        if k % 50 == 0:
            loads.append(os.getloadavg()[0])
        k += 1
        time.sleep(args.every)
    seconds = time.perf_counter() - t0
    kernel_peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024.0  # largest child that ended
    figures = {
        "command": cmd,
        "exit": proc.returncode,
        "seconds": seconds,
        "main_peak_mb": peak_main,
        "main_end_mb": trace[-1][1] if trace else 0.0,
        "largest_descendant_peak_mb": peak_child,
        "ru_maxrss_children_mb": kernel_peak,
        "load_average": {"min": min(loads), "max": max(loads), "mean": sum(loads) / len(loads)},
        "samples": len(trace),
    }
    print(
        f"exit {proc.returncode} after {seconds:.0f} s; main process peak RSS {peak_main:.0f} MB (sampled every "
        f"{args.every:g} s; kernel's peak over the children {kernel_peak:.0f} MB), largest worker {peak_child:.0f} MB; "
        f"load average {figures['load_average']['mean']:.1f} (min {min(loads):.1f}, max {max(loads):.1f})"
    )
    if args.json:
        args.json.write_text(json.dumps({**figures, "trace": trace}, indent=1))
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
