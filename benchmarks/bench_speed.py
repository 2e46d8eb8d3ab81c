"""Speed of vloop's two paths on five mechanisms, against the hand closed forms and pylinkage, in one process.

    python benchmarks/bench_speed.py                       # 4,800 and 48,000 steps, every mechanism
    python benchmarks/bench_speed.py --steps 4800 --repeat 30 --only eightbar

Mechanisms: the paper's eight-bar, the textbook four-bar, the offset slider-crank, the Stephenson III
six-bar driven at its output rocker (a coupled two-loop Newton block on the auto path) and the Jansen
pair. Each is solved over its file's time span with ``steps`` samples:

* ``auto``: closed-form dyads where the structure allows, Newton blocks elsewhere — ``solve(system)``;
* ``newton``: one Newton block for the whole system — ``solve(system, method="newton")``;
* ``solve(mech)``: the same as auto with compilation included (a new Mechanism object per call), and
  compiled once (the same Mechanism again: vloop.solve keeps a Mechanism's compiled system);
* ``closed form``: the hand-derived closed form in numpy (validators.analytic), where one exists;
* ``pylinkage``: pylinkage's numba path with velocities and accelerations (``step_fast_with_kinematics``),
  for the three mechanisms it can express (its numba compile time is excluded and reported). pylinkage
  turns its crank at a constant rate per step, so it runs the same geometry at the file's initial ω.

Times are the best of ``--repeat`` rounds in which every contender runs once in turn (a burst of load on a
shared machine then falls on all of them alike). BLAS and numba run one thread (threadpoolctl,
NUMBA_NUM_THREADS=1): the products are small, and a second thread only competes for the other core with
whatever runs next. vloop asks glibc to keep freed heap for reuse (vloop.files.budget.keep_heap, at its first
solve; the whole process, so every contender here runs with it); ``VLOOP_KEEP_HEAP=0 python
benchmarks/bench_speed.py`` measures without it. Every run is checked: auto against the
closed form (1e-9 of peak) and newton against auto.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
# numba's second thread (pylinkage) otherwise competes with whatever runs next on a 2-core machine: measured
# 3.8 ms for vloop's eight-bar run between pylinkage runs vs 2.6 ms with one, pylinkage itself 2.7 vs 2.2 ms
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from validators import analytic  # noqa: E402
from vloop.files.budget import keep_heap  # noqa: E402

MECHANISMS = (
    "eightbar",
    "fourbar_textbook_example",
    "slider_crank_offset",
    "sixbar_stephenson3_output_driven",
    "jansen_pair",
)


def best_of(fn: Callable[[], object], repeat: int) -> float:
    return best_of_each({"": fn}, repeat)[""]


def best_of_each(fns: dict[str, Callable[[], object]], repeat: int) -> dict[str, float]:
    """The best time of each function over ``repeat`` rounds (:func:`rounds_of_each`)."""
    return {label: min(times, default=math.inf) for label, times in rounds_of_each(fns, repeat).items()}


def rounds_of_each(fns: dict[str, Callable[[], object]], repeat: int) -> dict[str, list[float]]:
    """The time of each function in each of ``repeat`` rounds, the functions taking turns within a round: a burst
    of load on a shared machine then falls on all of them alike, not on whichever ran during it. Each turn calls
    its function twice and times the second call: it then finds the caches and the heap as its own last call left
    them, not as the function before it did (the first of a round measured 5–25 % slower than the same call
    later in it)."""
    times: dict[str, list[float]] = {label: [] for label in fns}
    for _ in range(repeat):
        for label, fn in fns.items():
            fn()
            t0 = time.perf_counter()
            fn()
            times[label].append(time.perf_counter() - t0)
    return times


def worst_relative(a: vloop.Result, b: vloop.Result) -> float:
    """Largest |a − b| over the columns both have, relative to each column's peak (groups near 0 skipped)."""
    worst = 0.0
    for c in b.columns:
        if c in a.columns:
            peak = float(np.max(np.abs(b[c])))
            if peak > 1e-9:
                worst = max(worst, float(np.max(np.abs(a[c] - b[c]))) / peak)
    return worst


# ---------------------------------------------------------------- pylinkage models of the shared mechanisms


def pylinkage_model(name: str, mech: vloop.Mechanism, dt: float):
    """The mechanism as a pylinkage Linkage turning its crank ω·dt per step, or None if not one of the three."""
    import pylinkage as pl

    if name not in ("eightbar", "fourbar_textbook_example", "slider_crank_offset"):
        return None
    d = mech.drivers[0]
    j = mech.joints
    O2 = pl.Ground(*j["O2"], name="O2")
    parts: list = [O2]
    if name == "eightbar":
        crank = pl.Crank(O2, radius=3.0, angular_velocity=d.v0 * dt, initial_angle=d.x0, name="A")
        x0, x1 = pl.Ground(0.0, 0.0, name="x0"), pl.Ground(1.0, 0.0, name="x1")
        v0, v1, v2 = pl.Ground(8.0, 0.0, name="v0"), pl.Ground(8.0, 1.0, name="v1"), pl.Ground(8.0, -1.0, name="v2")
        B = pl.RRPDyad(crank.output, x0, x1, distance=5.0, x=j["B"][0], y=j["B"][1], name="B")
        C = pl.RRPDyad(B, v0, v1, distance=6.15, x=j["C"][0], y=j["C"][1], name="C")
        D = pl.RRPDyad(B, v0, v2, distance=6.15, x=j["D"][0], y=j["D"][1], name="D")
        parts += [x0, x1, v0, v1, v2, crank, B, C, D]
    elif name == "fourbar_textbook_example":
        O4 = pl.Ground(*j["O4"], name="O4")
        crank = pl.Crank(O2, radius=40.0, angular_velocity=d.v0 * dt, initial_angle=d.x0, name="A")
        B = pl.RRRDyad(crank.output, O4, distance1=120.0, distance2=80.0, x=j["B"][0], y=j["B"][1], name="B")
        parts += [O4, crank, B]
    elif name == "slider_crank_offset":
        r0, r1 = pl.Ground(0.0, 1.0, name="r0"), pl.Ground(1.0, 1.0, name="r1")
        crank = pl.Crank(O2, radius=2.0, angular_velocity=d.v0 * dt, initial_angle=d.x0, name="A")
        B = pl.RRPDyad(crank.output, r0, r1, distance=6.0, x=j["B"][0], y=j["B"][1], name="B")
        parts += [r0, r1, crank, B]
    else:
        return None
    model = pl.Linkage(parts, name=name)
    model.set_input_velocity(crank, d.v0, 0.0)
    return model


def pylinkage_run(model, n: int):
    """n steps of P/V/A (a model continues from where its last run ended: the cost is the same)."""
    return model.step_fast_with_kinematics(iterations=n, dt=1.0)


def pylinkage_check(name: str, mech: vloop.Mechanism, n: int, dt: float) -> float:
    """Largest gap between a fresh pylinkage model's joints and vloop's at constant ω (fraction of the peak of
    positions, velocities, accelerations: the worst of the three)."""
    data = vloop.mechanism.to_dict(mech)
    data["drivers"][0]["alpha"] = 0.0
    const = vloop.from_dict(data, source=mech.source)
    model = pylinkage_model(name, mech, dt)
    pva = pylinkage_run(model, n)
    res = vloop.solve(const, dt * np.arange(1, n + 1))
    named = [(k, jt.name) for k, jt in enumerate(model.components) if jt.name in mech.tracked_points]
    worst = 0.0
    for arr, (fx, fy) in zip(pva, (("x", "y"), ("vx", "vy"), ("ax", "ay")), strict=True):
        ours = {p: np.column_stack([res[f"{p}.{fx}"], res[f"{p}.{fy}"]]) for _, p in named}
        peak = max(float(np.max(np.abs(o))) for o in ours.values())
        worst = max(worst, max(float(np.max(np.abs(arr[:, k] - ours[p]))) for k, p in named) / peak)
    return worst


# ---------------------------------------------------------------- main


def bench(name: str, steps: list[int], repeat: int, have_pylinkage: bool) -> list[str]:
    mech = vloop.load(ROOT / "mechanisms" / f"{name}.toml")
    system = vloop.compile(mech)
    lines = []
    t_compile = best_of(lambda: vloop.compile(mech), repeat)
    lines.append(f"{name}: compile {t_compile * 1e3:.2f} ms; blocks {[b.kind for b in system.blocks]}")
    per_step = {}
    for n in steps:
        t = np.linspace(mech.times[0], mech.times[-1], n)
        res = vloop.solve(system, t)
        newton = vloop.solve(system, t, method="newton")
        gap_newton = worst_relative(newton, res)
        fns: dict[str, Callable[[], object]] = {
            "auto: solve(system)": lambda t=t: vloop.solve(system, t),
            "newton: solve(system, method=newton)": lambda t=t: vloop.solve(system, t, method="newton"),
            # a new Mechanism object per call: compiled every time (vloop.solve keeps a Mechanism's system)
            "auto: solve(mech), compile included": lambda t=t: vloop.solve(dataclasses.replace(mech), t),
            "auto: solve(mech), compiled once": lambda t=t: vloop.solve(mech, t),
        }
        check = f"newton vs auto {gap_newton:.1e}"
        if analytic.available(mech):
            ref = analytic.solve(mech, t)
            check += f"; auto vs closed form {worst_relative(res, ref):.1e}, newton {worst_relative(newton, ref):.1e}"
            fns["closed form (numpy, by hand)"] = lambda t=t: analytic.solve(mech, t)
        model = pylinkage_model(name, mech, float(t[1] - t[0])) if have_pylinkage else None
        if model is not None:
            dt = float(t[1] - t[0])
            t0 = time.perf_counter()
            pylinkage_run(model, 2)  # numba compiles on the first call
            jit = time.perf_counter() - t0
            fns["pylinkage numba P/V/A"] = lambda model=model, n=n: pylinkage_run(model, n)
            check += f"; pylinkage P/V/A vs vloop {pylinkage_check(name, mech, n, dt):.1e} of peak"
            check += f" (pylinkage first call incl. numba compile {jit:.2f} s, excluded)"
        times = best_of_each(fns, repeat)
        t_auto, t_pl = times["auto: solve(system)"], times.get("pylinkage numba P/V/A")
        per_step[n] = t_auto / n
        rows = list(times.items())
        lines.append(f"  {n:,} steps — {check}")
        for label, tt in rows:
            vs_pl = f"{tt / t_pl:8.2f}x pylinkage" if t_pl else ""
            lines.append(
                f"    {label:<40} {tt * 1e3:9.3f} ms {n / tt:>12,.0f} steps/s {tt / t_auto:8.2f}x auto {vs_pl}"
            )
    if len(per_step) > 1:
        a, b = sorted(per_step)[0], sorted(per_step)[-1]
        lines.append(f"  auto: time per step at {b:,} / at {a:,} = {per_step[b] / per_step[a]:.2f}")
    return lines


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--steps", type=int, nargs="+", default=[4800, 48000])
    p.add_argument("--repeat", type=int, default=10)
    p.add_argument("--only", nargs="+", default=list(MECHANISMS), choices=MECHANISMS)
    args = p.parse_args(argv)
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # the environment variables above already ask for one thread
        threadpool_limits = None
    try:
        import pylinkage  # noqa: F401

        have_pylinkage = True
    except ImportError:
        have_pylinkage = False
        print("pylinkage not installed (pip install 'vloop[bench]'): no pylinkage baseline\n")
    ctx = threadpool_limits(1) if threadpool_limits else None
    kept = keep_heap()  # what vloop's first solve does; every contender runs in this process after it
    print(
        "allocator: glibc keeps freed heap for reuse (vloop's default)"
        if kept
        else "allocator: system default (VLOOP_KEEP_HEAP=0, MALLOC_* set, or not glibc): temporaries are page-faulted"
    )
    try:
        for name in args.only:
            print("\n".join(bench(name, args.steps, args.repeat, have_pylinkage)), flush=True)
    finally:
        if ctx is not None:
            ctx.unregister() if hasattr(ctx, "unregister") else None
    return 0


if __name__ == "__main__":
    sys.exit(main())
