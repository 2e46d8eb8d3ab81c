"""Forward dynamics: vloop.simulate against Exudyn's time integration of the same model, in one process.

    python benchmarks/bench_simulate.py                       # the eight-bar, gravity, its payload, a motor line, 10 s
    python benchmarks/bench_simulate.py --stop 2 --exudyn-step 2e-4

The eight-bar with masses (mechanisms/eightbar_dynamics.toml: gravity and its 500 N payload) driven by the motor
line T = 1000 N·m·(1 − ω/5 rad/s) from its file state (θ₂ = 90°, ω₂ = 3 rad/s). Prints:

* vloop.simulate's time (best of ``--repeat``, the tables' build included) at ``--rtol`` and its error in the
  crank angle over the run, against the same simulation at rtol = 1e-13 and against Exudyn's run corrected by
  Richardson's extrapolation (steps h and h/2: validators/dynamics_exudyn.py);
* Exudyn's time for one run at h (validators/dynamics_exudyn.py's model: generalized-α, second order) and its
  own error at h (from the same extrapolation), and the ratio of the two times.

Target: 10 s of this motion at 1e-9 rad accuracy in under a second. Exudyn reaches that accuracy only with
steps far below what is timed here (its error falls as h²), so the time ratio is at *unequal* accuracy, in
Exudyn's favour.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from vloop.model import Dynamics  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--stop", type=float, default=10.0, help="simulated time [s]")
    p.add_argument("--rtol", type=float, default=1e-12, help="simulate's rtol = atol")
    p.add_argument("--exudyn-step", type=float, default=1e-4, help="Exudyn's step h [s] (also run at h/2)")
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    mech = vloop.load(ROOT / "mechanisms" / "eightbar_dynamics.toml")
    mech = dataclasses.replace(mech, dynamics=Dynamics(motor=(1000.0, 5.0)))
    times = np.linspace(0.0, args.stop, 101)
    vloop.simulate(mech, times[:3])  # imports and the first compile out of the timing

    best = np.inf
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        sim = vloop.simulate(mech, times, rtol=args.rtol, atol=args.rtol)
        best = min(best, time.perf_counter() - t0)
    ref = vloop.simulate(mech, times, rtol=1e-13, atol=1e-13)
    theta = sim.result["l2.theta"]
    print(
        f"eight-bar, gravity, 500 N payload, motor 1000 N·m·(1 − ω/5): {args.stop:g} s, {ref.ode.nfev} evaluations "
        f"at rtol 1e-13, θ₂ from {theta[0]:.6f} to {theta[-1]:.6f} rad"
    )
    print(
        f"vloop.simulate  rtol {args.rtol:g}: {best:.3f} s (best of {args.repeat}, {sim.ode.nfev} evaluations); "
        f"|θ₂ − θ₂(rtol 1e-13)| ≤ {np.abs(theta - ref.result['l2.theta']).max():.2e} rad"
    )

    from validators import dynamics_exudyn

    t0 = time.perf_counter()
    coarse = dynamics_exudyn._run(mech, times, args.exudyn_step)
    exu_time = time.perf_counter() - t0
    fine = dynamics_exudyn._run(mech, times, args.exudyn_step / 2)
    exact = fine["l2.theta"] + (fine["l2.theta"] - coarse["l2.theta"]) / 3
    print(
        f"Exudyn  h = {args.exudyn_step:g} s: {exu_time:.3f} s per run; its own error at h "
        f"{np.abs(coarse['l2.theta'] - exact).max():.2e} rad"
    )
    print(f"|vloop − Exudyn (Richardson, h and h/2)| ≤ {np.abs(theta - exact).max():.2e} rad")
    print(f"time ratio Exudyn / vloop: {exu_time / best:.1f}")


if __name__ == "__main__":
    main()
