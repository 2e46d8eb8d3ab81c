"""Throughput at any sampling: the same number of samples spread over more and more turns of the input.

    python benchmarks/bench_sampling.py                       # the table: 4,800 samples, 1 / 20 / 115 / 400 turns
    python benchmarks/bench_sampling.py --only eightbar --repeat 3
    python benchmarks/bench_sampling.py --compare main        # main's times too, in this process (a commit or folder)

Each column samples the input ``--samples`` times, evenly in input angle, over 1, 20, 115 and 400 turns
(0.075°, 1.5°, 8.6° and 30° of input per sample at 4,800 samples; 8.6° is the paper's own eight-bar grid). A
crank with an angular acceleration is sampled at the times its angle reaches those values (θ − θ0 = ω0·t +
α·t²/2 solved for t), so every sample moves the input equally. The output-driven six-bar's input rocker cannot
turn: it is driven by a tabulated rocking θ6(t) = θ6(0) + A·(1 − cos 2πt/T) that stays 0.05 rad short of its
upper limit, one rocking period counting as one turn (its phase per sample as the angle).

Printed: samples per second of ``vloop.solve(system, t)`` (auto) and ``method="newton"``, each column's time per
sample as a ratio to the first column's. Times are the best of ``--repeat`` rounds in which every contender runs
once in turn (:func:`bench_speed.rounds_of_each`); the median is printed next to the best. BLAS runs one thread.
With ``--compare REF`` the same runs of another version (a git commit, or a source folder) are timed in this
process as well, interleaved with this tree's (its package imported as ``vloop_ref``: its modules import one
another relatively), and the ratio of this tree's time to the other's is printed per cell: a before/after in one
process on a shared machine.

Every run is checked: auto against the closed form where one exists (validators.analytic; the largest gap as a
fraction of each column's peak), newton against auto, and (with ``--compare``) each tree's run against the
other's.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "benchmarks"))

from bench_speed import worst_relative  # noqa: E402

import vloop  # noqa: E402
from validators import analytic  # noqa: E402
from vloop.files.budget import keep_heap  # noqa: E402

MECHANISMS = (
    "fourbar_crank_rocker_open",
    "slider_crank_offset",
    "eightbar",
    "sixbar_stephenson3_output_driven",
    "jansen_pair",
)
TURNS = (1, 20, 115, 400)
ROCKING = "sixbar_stephenson3_output_driven"
ROCK_TOP = 2.3220 - 0.05  # the six-bar's input rocker stays this far below its upper limit [rad]
ROCK_PERIOD = 2.0  # [s] one rocking period of the six-bar's input
ROCK_ROWS = 64  # profile rows per period (θ, ω, α given: a quintic Hermite spline)


def rocking(lib, mech: vloop.Mechanism, periods: int) -> vloop.Mechanism:
    """The six-bar driven by θ6(t) = θ6(0) + A·(1 − cos 2πt/T) over ``periods`` periods (a tabulated profile)."""
    d = mech.drivers[0]
    amp = 0.5 * (ROCK_TOP - d.x0)
    w = 2 * math.pi / ROCK_PERIOD
    t = np.linspace(0.0, periods * ROCK_PERIOD, periods * ROCK_ROWS + 1)
    profile = lib.model.Profile(
        t, d.x0 + amp * (1 - np.cos(w * t)), amp * w * np.sin(w * t), amp * w * w * np.cos(w * t)
    )
    return dataclasses.replace(mech, drivers=(dataclasses.replace(d, profile=profile),))


EVEN = ["angle"]  # how the samples are spread: evenly in the input's angle, or ("time") evenly in time


def sample_times(mech: vloop.Mechanism, turns: int, n: int) -> np.ndarray:
    """``n`` times at which the input has turned evenly over ``turns`` turns (of its crank, or rocking periods);
    with EVEN = ["time"], ``n`` times evenly spaced up to the time of the last turn."""
    d = mech.drivers[0]
    if d.profile is not None:
        return np.linspace(0.0, turns * ROCK_PERIOD, n)
    angle = np.linspace(0.0, turns * 2 * math.pi, n)
    if d.a0 == 0.0:
        return angle / abs(d.v0)
    t = (-d.v0 + np.sqrt(d.v0 * d.v0 + 2 * d.a0 * angle)) / d.a0  # θ − θ0 = ω0·t + α·t²/2, ω0, α > 0
    return np.linspace(0.0, t[-1], n) if EVEN[0] == "time" else t


@dataclasses.dataclass
class Case:
    """One mechanism at one sampling, in one tree: its compiled systems and times."""

    name: str
    turns: int
    mech: vloop.Mechanism
    system: object
    times: np.ndarray


def rounds_of_each(fns: dict[str, Callable[[], object]], repeat: int) -> dict[str, list[float]]:
    """As bench_speed.rounds_of_each (each function called twice a turn, the second call timed; the functions
    take turns within a round), every other round in the reverse order: neither tree always runs first."""
    times: dict[str, list[float]] = {label: [] for label in fns}
    labels = list(fns)
    for r in range(repeat):
        for label in labels if r % 2 == 0 else labels[::-1]:
            fns[label]()
            t0 = time.perf_counter()
            fns[label]()
            times[label].append(time.perf_counter() - t0)
    return times


def load_tree(ref: str) -> object:
    """vloop as of ``ref`` (a git commit, or a source folder) imported as a package of its own name (``vloop_ref``):
    its modules import one another relatively, so they never reach this tree's."""
    folder = Path(tempfile.mkdtemp(prefix="vloop_ref_"))
    source = Path(ref)
    if source.is_dir():
        shutil.copytree(source / "vloop", folder / "vloop_ref", ignore=shutil.ignore_patterns("__pycache__"))
    else:
        archive = subprocess.run(
            ["git", "-C", str(ROOT), "archive", ref, "vloop"], capture_output=True, check=True
        ).stdout
        subprocess.run(["tar", "-x", "-C", str(folder)], input=archive, check=True)
        (folder / "vloop").rename(folder / "vloop_ref")
    sys.path.insert(0, str(folder))
    return importlib.import_module("vloop_ref")


def cases(lib, name: str, turns: tuple[int, ...], n: int) -> list[Case]:
    mech = lib.load(ROOT / "mechanisms" / f"{name}.toml")
    out = []
    for k in turns:
        m = rocking(lib, mech, k) if name == ROCKING else mech
        out.append(Case(name, k, m, lib.compile(m), sample_times(m, k, n)))
    return out


def degrees_per_sample(turns: int, n: int) -> float:
    return 360.0 * turns / (n - 1)


def bench(name: str, turns: tuple[int, ...], n: int, repeat: int, other) -> list[str]:
    mine = cases(vloop, name, turns, n)
    theirs = cases(other, name, turns, n) if other is not None else None
    lines = [f"{name}:"]
    fns: dict[str, Callable[[], object]] = {}
    checks = []
    for j, c in enumerate(mine):
        for method in ("auto", "newton"):
            fns[f"{method} {c.turns}"] = lambda c=c, m=method: vloop.solve(c.system, c.times, method=m)
            if theirs is not None:
                o = theirs[j]
                fns[f"{method} {c.turns} other"] = lambda o=o, m=method: other.solve(o.system, o.times, method=m)
        auto = vloop.solve(c.system, c.times)
        newton = vloop.solve(c.system, c.times, method="newton")
        note = f"newton vs auto {worst_relative(newton, auto):.1e}"
        if analytic.available(c.mech):
            ref = analytic.solve(c.mech, c.times)
            note += f", auto vs closed form {worst_relative(auto, ref):.1e}, newton {worst_relative(newton, ref):.1e}"
        if theirs is not None:
            o = theirs[j]
            for method, res in (("auto", auto), ("newton", newton)):
                note += f", {method} vs other {worst_relative(res, other.solve(o.system, o.times, method=method)):.1e}"
        checks.append(f"  {degrees_per_sample(c.turns, n):7.3f}°/sample: {note}")
    rounds = rounds_of_each(fns, repeat)
    best = {k: min(v) for k, v in rounds.items()}
    med = {k: statistics.median(v) for k, v in rounds.items()}
    head = "".join(f"{degrees_per_sample(k, n):>10.3f}°/s ({k:>3} turns)" for k in turns)
    lines.append(f"  {'':<16}{head}")
    for method in ("auto", "newton"):
        for tree in ("", " other") if theirs is not None else ("",):
            label = f"{method}{' (other)' if tree else ''}"
            first = best[f"{method} {turns[0]}{tree}"]
            cells = "".join(
                f"{n / best[f'{method} {k}{tree}'] / 1e6:>9.3f} M/s ({best[f'{method} {k}{tree}'] / first:5.2f}×)"
                for k in turns
            )
            lines.append(f"  {label:<16}{cells}")
            medians = "".join(f"{n / med[f'{method} {k}{tree}'] / 1e6:>9.3f} M/s {'':9}" for k in turns)
            lines.append(f"  {'  median':<16}{medians}")
        if theirs is not None:
            ratios = "".join(f"{best[f'{method} {k}'] / best[f'{method} {k} other']:>14.2f}× {'':9}" for k in turns)
            lines.append(f"  {method + ' this/other':<16}{ratios}")
            ratios = "".join(f"{med[f'{method} {k}'] / med[f'{method} {k} other']:>14.2f}× {'':9}" for k in turns)
            lines.append(f"  {'  medians':<16}{ratios}")
    lines.extend(checks)
    return lines


BIG = ["fourbar_crank_rocker_open"]  # the mechanism of the long runs (--big-mechanism)


def big_file(folder: Path, samples: int, turns: int) -> Path:
    """The mechanism's file with [time] over ``turns`` turns of its crank in ``samples`` samples, evenly in time
    (θ2 − θ2(0) = ω0·t + α·t²/2 solved for the stop time)."""
    text = (ROOT / "mechanisms" / f"{BIG[0]}.toml").read_text(encoding="utf-8")
    mech = vloop.load(ROOT / "mechanisms" / f"{BIG[0]}.toml")
    d = mech.drivers[0]
    angle = turns * 2 * math.pi
    stop = (-d.v0 + math.sqrt(d.v0 * d.v0 + 2 * d.a0 * angle)) / d.a0 if d.a0 else angle / d.v0
    step = stop / (samples - 1)
    path = folder / f"{BIG[0]}_{turns}.toml"
    path.write_text(
        text.split("[time]")[0] + f"[time]\nstart = 0.0\nstop = {stop!r}\nstep = {step!r}\n", encoding="utf-8"
    )
    return path


def big_run(samples: int, turns: int, fmt: str = "parquet") -> tuple[float, float, int]:
    """(seconds, peak RSS [MB], rows written) of ``vloop run FILE --format parquet`` in a process of its own (the
    peak is that process's ru_maxrss, read by a wrapper so runs never mix)."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        path = big_file(folder, samples, turns)
        probe = (
            "import resource, sys, time; from vloop.cli import main; t0 = time.perf_counter(); "
            f"rc = main(['run', {str(path)!r}, '--out', {str(folder / 'out')!r}, '--format', {fmt!r}]); "
            "print(time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, rc)"
        )
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        proc = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, env=env, check=False)
        seconds, peak, rc = proc.stdout.strip().splitlines()[-1].split()
        if rc != "0":
            raise SystemExit(proc.stdout + proc.stderr)
        import pyarrow.parquet as pq

        rows = pq.ParquetFile(folder / "out" / "results.parquet").metadata.num_rows
    return float(seconds), float(peak) / 1024.0, rows


def big_table(samples: int, repeat: int) -> list[str]:
    """The million-sample runs over one turn and over 10,000 turns, interleaved ``repeat`` times: medians."""
    runs: dict[int, list[tuple[float, float, int]]] = {1: [], 10_000: []}
    for _ in range(repeat):
        for turns in runs:
            runs[turns].append(big_run(samples, turns))
    lines = [f"vloop run {BIG[0]} --format parquet, {samples:,} samples (median of {repeat}):"]
    base = statistics.median(r[0] for r in runs[1])
    for turns, rs in runs.items():
        t, peak = statistics.median(r[0] for r in rs), statistics.median(r[1] for r in rs)
        lines.append(
            f"  {turns:>6,} turns ({degrees_per_sample(turns, samples):7.4f}°/sample): {t:6.2f} s "
            f"({samples / t / 1e3:6.0f} k samples/s, {t / base:4.2f}× one turn), peak RSS {peak:5.0f} MB, "
            f"{rs[0][2]:,} rows written; all times {', '.join(f'{r[0]:.2f}' for r in rs)} s"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--samples", type=int, default=4800)
    p.add_argument("--turns", type=int, nargs="+", default=list(TURNS))
    p.add_argument("--repeat", type=int, default=5)
    p.add_argument("--only", nargs="+", default=list(MECHANISMS), choices=MECHANISMS)
    p.add_argument("--compare", default=None, help="a git commit or source folder timed alongside this tree")
    p.add_argument("--even", choices=["angle", "time"], default="angle", help="samples evenly in input or in time")
    p.add_argument("--big", type=int, default=0, help="also N-sample `vloop run`s over 1 and 10,000 turns")
    p.add_argument("--big-repeat", type=int, default=3)
    p.add_argument("--big-mechanism", default=BIG[0], choices=MECHANISMS[:3] + MECHANISMS[4:])
    args = p.parse_args(argv)
    try:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
    except ImportError:  # the environment variables above already ask for one thread
        pass
    keep_heap()
    EVEN[0] = args.even
    BIG[0] = args.big_mechanism
    other = load_tree(args.compare) if args.compare else None
    print(f"load average at start: {os.getloadavg()[0]:.2f}")
    for name in args.only:
        print("\n".join(bench(name, tuple(args.turns), args.samples, args.repeat, other)), flush=True)
    if args.big:
        print("\n".join(big_table(args.big, args.big_repeat)), flush=True)
    print(f"load average at end: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
