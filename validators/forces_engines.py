"""Every engine with its forces: for a mechanism with masses or loads, the Result an engine returns in
``vloop validate`` also holds the force columns (docs/forces.md), so the harness compares forces
next to positions, velocities and accelerations with the same code and tolerances.

* vloop: :func:`vloop.solve` then :func:`vloop.forces.solve_forces`;
* analytic: the kinematic closed form, then :mod:`validators.analytic_forces` where it applies
  (slider-crank, four-bar);
* pinocchio: :mod:`validators.pinocchio_forces` (inverse dynamics with the loop-closure forces);
* exudyn-kinematic / exudyn-dynamic: :mod:`validators.exudyn_forces` (Exudyn's multipliers).

A run that stops part-way keeps its forces on the samples it solved (``exc.partial``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from vloop.errors import MotionError
from vloop.forces import ForceResult, has_forces, solve_forces
from vloop.mechanism import Mechanism
from vloop.result import Result


def merge(kin: Result, forces: ForceResult) -> Result:
    """One Result with the kinematic columns and the force columns (same samples)."""
    n = min(len(kin), len(forces))
    kin = kin.head(n)
    return Result(kin.mechanism, kin.engine, kin.t, {**kin.columns, **forces.head(n).columns}, kin.health, kin.meta)


def _then_forces(fn: Callable[[Mechanism], Result], forces: Callable[[Mechanism, Result], ForceResult]) -> Callable:
    def run(mech: Mechanism) -> Result:
        try:
            res = fn(mech)
        except (MotionError, ValueError) as exc:
            part = getattr(exc, "partial", None)
            if isinstance(part, Result) and len(part):
                exc.partial = merge(part, forces(mech, part))  # type: ignore[attr-defined]
            raise
        return merge(res, forces(mech, res))

    return run


def with_forces(name: str, fn: Callable[[Mechanism], Result]) -> Callable[[Mechanism], Result]:
    """``fn`` (engine ``name``'s kinematics) extended with that engine's own forces when the mechanism has any."""

    def run(mech: Mechanism) -> Result:
        if not has_forces(mech):
            return fn(mech)
        if name == "vloop":
            return _then_forces(fn, solve_forces)(mech)
        if name == "analytic":
            from . import analytic_forces

            if not analytic_forces.available(mech):
                return fn(mech)
            return _then_forces(fn, lambda m, r: analytic_forces.solve_forces(m, kinematics=r))(mech)
        if name == "pinocchio":
            from . import pinocchio_forces

            return _unpack(pinocchio_forces.solve_with_forces, mech)
        if name.startswith("exudyn-"):
            from . import exudyn_forces

            return _unpack(lambda m: exudyn_forces.solve_with_forces(m, mode=name.split("-", 1)[1]), mech)
        return fn(mech)

    return run


def _unpack(solve: Callable[[Mechanism], tuple[Result, ForceResult]], mech: Mechanism) -> Result:
    """A (kinematics, forces) engine as one Result; its MotionError's (kinematics, forces) partial too."""
    try:
        kin, frc = solve(mech)
    except MotionError as exc:
        part: Any = exc.partial
        if isinstance(part, tuple):
            exc.partial = merge(*part)
        raise
    return merge(kin, frc)
