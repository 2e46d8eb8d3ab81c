"""CPU of the Pinocchio kinematic engine (``validators.pinocchio.solve``) over a folder of mechanism files, and
its results against a reference run (saved, or an older revision of the engine run in the same process).

    vloop corpus --n 300 --seed 2026 --out /tmp/pin_c300
    python benchmarks/bench_pinocchio.py /tmp/pin_c300 --save /tmp/pin_ref.npz        # record a reference run
    python benchmarks/bench_pinocchio.py /tmp/pin_c300 --compare /tmp/pin_ref.npz     # CPU ratio and differences
    python benchmarks/bench_pinocchio.py /tmp/pin_c300 --baseline main                # against main's engine, here

Each mechanism is loaded with ``vloop.load`` (not timed) and solved over its file's times; a MotionError counts as
a run that stops, its partial result is what is compared. CPU is ``time.process_time()`` around ``solve`` alone
(SciPy's splines are imported and the first file is solved once, untimed, before: imports and first calls).
Prints the total CPU, ms per mechanism and, against the reference, the CPU ratio (reference / this) and the worst
|difference| / peak of every output column and of the joint coordinates q, v, a (column by column, over each
run), the worst relative difference of the health's ``cond`` and ``residual``, and any run whose stop differs
(number of samples or error text). ``--baseline REV`` loads ``validators/pinocchio.py`` of git revision REV as a
module and runs it on the same mechanism right before this one (so both see the same machine load). BLAS runs
one thread.
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import subprocess
import sys
import time
from pathlib import Path
from types import ModuleType
from typing import Any

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from validators import pinocchio as vpin  # noqa: E402
from vloop.errors import MotionError  # noqa: E402

HEALTH = ("cond", "residual", "iterations")
META = ("q", "v", "a")


def baseline_module(rev: str) -> ModuleType:
    """validators/pinocchio.py at git revision ``rev``, as module ``validators._pinocchio_baseline``."""
    src = subprocess.run(
        ["git", "-C", str(ROOT), "show", f"{rev}:validators/pinocchio.py"], check=True, capture_output=True, text=True
    ).stdout
    spec = importlib.util.spec_from_loader("validators._pinocchio_baseline", loader=None)
    assert spec is not None
    mod = importlib.util.module_from_spec(spec)
    mod.__package__ = "validators"
    sys.modules[spec.name] = mod
    exec(compile(src, f"{rev}:validators/pinocchio.py", "exec"), mod.__dict__)
    return mod


def run(engine: ModuleType, mech: Any) -> tuple[dict[str, np.ndarray], str, float]:
    """(arrays of the run, error text or "", CPU seconds) of ``engine.solve(mech)``."""
    t0 = time.process_time()
    try:
        res, err = engine.solve(mech), ""
    except MotionError as exc:
        res, err = exc.partial, str(exc)
    cpu = time.process_time() - t0
    arrays = {"t": res.t, **res.columns}
    arrays.update({f"health.{k}": res.health[k] for k in HEALTH})
    arrays.update({f"meta.{k}": res.meta[k] for k in META})
    return arrays, err, cpu


def differences(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> dict[str, float]:
    """Worst |a − b| / peak over the columns (peak: of b's column; health: per sample) by kind of column."""
    out = {"columns": 0.0, "q v a": 0.0, "cond": 0.0, "residual": 0.0, "iterations": 0.0}
    for k, ref in b.items():
        x = a[k]
        if x.shape != ref.shape:
            return {kind: np.inf for kind in out}
        if k.startswith("health."):  # the scaled residual (~1e-16, often 0) absolutely, the others relatively
            kind = k.split(".", 1)[1]
            scale = 1.0 if kind == "residual" else np.maximum(np.abs(ref), 1e-300)
            d = float(np.max(np.abs(x - ref) / scale, initial=0.0))
        else:
            kind = "q v a" if k.startswith("meta.") else "columns"
            cols = ref.reshape(len(ref), -1) if ref.ndim else ref
            peak = np.max(np.abs(cols), axis=0, initial=0.0)
            diff = np.max(np.abs(x.reshape(cols.shape) - cols), axis=0, initial=0.0)
            rel = np.where(peak > 0, diff / np.where(peak > 0, peak, 1.0), np.where(diff > 0, np.inf, 0.0))
            d = float(np.max(rel, initial=0.0))
        out[kind] = max(out[kind], d)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="folder of mechanism .toml files (vloop corpus --out)")
    ap.add_argument("--limit", type=int, default=0, help="only the first N files")
    ap.add_argument("--save", type=Path, help="write this run's results and CPU to an .npz")
    ap.add_argument("--compare", type=Path, help="compare with an .npz written by --save")
    ap.add_argument("--baseline", help="git revision whose validators/pinocchio.py to run alongside, in-process")
    args = ap.parse_args()
    files = sorted(args.folder.glob("*.toml"))[: args.limit or None]
    base = baseline_module(args.baseline) if args.baseline else None
    ref = dict(np.load(args.compare, allow_pickle=False)) if args.compare else {}
    import scipy.interpolate  # noqa: F401  (tabulated inputs' splines: imported at the first such file otherwise)

    for engine in filter(None, (base, vpin)):  # imports (Pinocchio) and first calls, untimed
        run(engine, vloop.load(files[0]))
    saved: dict[str, np.ndarray] = {}
    cpu = np.zeros(len(files))
    cpu_ref = np.full(len(files), np.nan)
    worst: dict[str, tuple[float, str]] = {}
    stops = []
    for i, path in enumerate(files):
        mech, name = vloop.load(path), path.stem
        if base is not None:
            ref_arrays, ref_err, cpu_ref[i] = run(base, mech)
        arrays, err, cpu[i] = run(vpin, mech)
        saved.update({f"{name}/{k}": v for k, v in arrays.items()})
        saved[f"{name}/error"], saved[f"{name}/cpu"] = np.array(err), np.array(cpu[i])
        if ref and base is None:
            ref_arrays = {k.split("/", 1)[1]: v for k, v in ref.items() if k.startswith(f"{name}/")}
            ref_err, cpu_ref[i] = str(ref_arrays.pop("error")), float(ref_arrays.pop("cpu"))
        if ref or base is not None:
            if ref_err != err or len(ref_arrays["t"]) != len(arrays["t"]):
                stops.append(f"{name}: {len(arrays['t'])} samples '{err}' vs {len(ref_arrays['t'])} '{ref_err}'")
            for kind, d in differences(arrays, ref_arrays).items():
                if d >= worst.get(kind, (-1.0, ""))[0]:
                    worst[kind] = (d, name)
    print(f"{len(files)} mechanisms, {sum(bool(saved[f'{p.stem}/error']) for p in files)} stop at a limit")
    print(f"this engine: {cpu.sum():.2f} s CPU, {1e3 * cpu.mean():.1f} ms per mechanism")
    if np.all(np.isfinite(cpu_ref)) and len(files):
        print(f"reference:   {cpu_ref.sum():.2f} s CPU, {1e3 * cpu_ref.mean():.1f} ms per mechanism")
        print(f"ratio reference / this: {cpu_ref.sum() / cpu.sum():.2f}x")
        for kind, (d, name) in worst.items():
            print(f"worst {kind:10s} |diff|/peak: {d:.3g}" + (f" ({name})" if d > 0 else ""))
        print(f"stops that differ: {len(stops)}", *stops, sep="\n  ")
    if args.save:
        np.savez_compressed(args.save, **saved)
        print(f"saved {args.save}")


if __name__ == "__main__":
    main()
