"""The engines of the validation harness: one small contract every engine implements, one table of them.

    engine = ENGINES["pinocchio"]
    if engine.applies(mech):
        res = engine.solve(mech)                 # kinematics over the file's times (the Result contract)
        res = engine.run(mech)                   # what `vloop validate` compares: + the engine's own forces

Like SciPy's ``OdeSolver`` subclasses (``solve_ivp``'s ``METHODS`` table), an engine is a subclass of
:class:`Engine` that sets ``name`` and implements ``solve``; registering it in :data:`ENGINES` is all the
harness needs. Each engine reads the Mechanism only and returns the same Result type; the imports of
Pinocchio and Exudyn happen inside ``solve`` so that the table itself is cheap to import.

Forces: for a mechanism with masses or loads, :meth:`Engine.run` returns one Result holding the
kinematic columns and the engine's own force columns (vloop: :func:`vloop.forces.solve_forces`; the closed
form: :mod:`validators.analytic.forces` where it applies; Pinocchio: inverse dynamics with the loop-closure
forces; Exudyn: its multipliers), so the harness compares forces with the same code and tolerances. A run
that stops part-way keeps its forces on the samples it solved (``exc.partial``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from vloop.errors import MotionError
from vloop.forces import ForceResult, has_forces, solve_forces
from vloop.mechanism import Mechanism
from vloop.result import Result

from .tolerances import DYNAMIC_STEPS


@dataclass
class SecondLook:
    """An engine's second look at its own run, asked for when another engine disagrees with it.

    ``result``: the run again, better by the engine's own measure (a finer step), on the same samples; it replaces
    the first. ``inconclusive``: why the engine cannot resolve the mechanism, from its own evidence only (its error
    estimate, step rejections, conditioning — never another engine's answer); the comparison is then inconclusive
    for this engine. ``note``: what was done, for the run's message.
    """

    result: Result | None = None
    inconclusive: str = ""
    note: str = ""


class Engine:
    """One engine: ``name``, ``solve(mechanism, times=None, **options) -> Result``, where it applies, its tolerances."""

    name: ClassVar[str] = ""

    def applies(self, mech: Mechanism) -> bool:
        """Whether the engine has anything to say about ``mech`` (closed forms exist for some structures only)."""
        return True

    def solve(self, mech: Mechanism, times: np.ndarray | None = None, **options: Any) -> Result:
        """Positions, velocities and accelerations over ``times`` [s] (default: the file's samples)."""
        raise NotImplementedError

    def with_forces(self, mech: Mechanism) -> Result:
        """Kinematics and the engine's own force columns (default: an engine without forces gives kinematics)."""
        return self.solve(mech)

    def run(self, mech: Mechanism) -> Result:
        """What the harness compares: the kinematics, with the forces when the mechanism has masses or loads."""
        return self.with_forces(mech) if has_forces(mech) else self.solve(mech)

    def second_look(self, mech: Mechanism, result: Result, stopped: bool) -> SecondLook | None:
        """Look again at ``result`` (this engine's run of ``mech``; ``stopped``: it ended early). None: nothing to add
        (an engine exact to round-off, or vloop itself, whose answer is what is being checked)."""
        return None

    def __repr__(self) -> str:
        return f"<engine {self.name}>"


class Vloop(Engine):
    """The product itself: :func:`vloop.solve`, forces by :func:`vloop.forces.solve_forces`."""

    name = "vloop"

    def solve(self, mech: Mechanism, times: np.ndarray | None = None, **options: Any) -> Result:
        import vloop

        return vloop.solve(mech, times, **options)

    def with_forces(self, mech: Mechanism) -> Result:
        return then_forces(self.solve, solve_forces, mech)


class Analytic(Engine):
    """The hand-derived closed forms (:mod:`validators.analytic`), forces where its `forces` module applies."""

    name = "analytic"

    def applies(self, mech: Mechanism) -> bool:
        from . import analytic

        return analytic.available(mech)

    def solve(self, mech: Mechanism, times: np.ndarray | None = None, **options: Any) -> Result:
        from . import analytic

        return analytic.solve(mech, times, **options)

    def with_forces(self, mech: Mechanism) -> Result:
        from .analytic import forces as analytic_forces

        if not analytic_forces.available(mech):
            return self.solve(mech)
        return then_forces(self.solve, lambda m, r: analytic_forces.solve_forces(m, kinematics=r), mech)


class Pinocchio(Engine):
    """Pinocchio with the loops cut and closed by constraints (:mod:`validators.pinocchio`)."""

    name = "pinocchio"

    def solve(self, mech: Mechanism, times: np.ndarray | None = None, **options: Any) -> Result:
        from . import pinocchio

        return pinocchio.solve(mech, times, **options)

    def with_forces(self, mech: Mechanism) -> Result:
        from . import pinocchio_forces

        return unpack(pinocchio_forces.solve_with_forces, mech)


class _Exudyn(Engine):
    """Exudyn's multibody model (:mod:`validators.exudyn`) in one of its two modes."""

    mode: ClassVar[str] = ""
    options: ClassVar[dict[str, Any]] = {}  # the harness's settings (given options win)

    def solve(self, mech: Mechanism, times: np.ndarray | None = None, **options: Any) -> Result:
        from . import exudyn

        return exudyn.solve(mech, times, mode=self.mode, **{**self.options, **options})

    def with_forces(self, mech: Mechanism) -> Result:
        from . import exudyn_forces

        return unpack(lambda m: exudyn_forces.solve_with_forces(m, mode=self.mode), mech)


class ExudynKinematic(_Exudyn):
    """Newton on Exudyn's own constraint equations at every sample."""

    name = "exudyn-kinematic"
    mode = "kinematic"


class ExudynDynamic(_Exudyn):
    """Exudyn's time integration (generalized-α) with the input prescribed, compared on the samples its first
    DYNAMIC_STEPS steps reach (validators/tolerances.py: what the comparison claims)."""

    name = "exudyn-dynamic"
    mode = "dynamic"
    options: ClassVar[dict[str, Any]] = {"max_steps": DYNAMIC_STEPS}

    def second_look(self, mech: Mechanism, result: Result, stopped: bool) -> SecondLook | None:
        """The window compared integrated again at finer steps, each run's error estimated from the one before
        (:func:`validators.exudyn.refine`); forces, if any, from the run kept."""
        from . import exudyn, exudyn_forces

        def with_forces(t: np.ndarray, accuracy: float) -> Result:
            return unpack(lambda m: exudyn_forces.solve_with_forces(m, t, mode=self.mode, accuracy=accuracy), mech)

        res, why, note = exudyn.refine(mech, result, stopped, with_forces if has_forces(mech) else None)
        return SecondLook(res, why, note)


class MuJoCo(Engine):
    """MuJoCo's simulation of the exported MJCF under its driver (:mod:`validators.mujoco`): positions and rates
    (no accelerations, no forces); optional (``--engines …,mujoco``)."""

    name = "mujoco"

    def solve(self, mech: Mechanism, times: np.ndarray | None = None, **options: Any) -> Result:
        from . import mujoco

        return mujoco.solve(mech, times, **options)


ENGINES: dict[str, Engine] = {
    e.name: e for e in (Vloop(), Analytic(), Pinocchio(), ExudynKinematic(), ExudynDynamic(), MuJoCo())
}


def engine(name: str) -> Engine:
    """The registered engine called ``name`` (ValueError naming the known ones otherwise)."""
    try:
        return ENGINES[name]
    except KeyError:
        raise ValueError(f"unknown engine '{name}' (known: {', '.join(ENGINES)})") from None


# ---------------------------------------------------------------- kinematics + forces in one Result


def merge(kin: Result, forces: ForceResult) -> Result:
    """One Result with the kinematic columns and the force columns (same samples)."""
    n = min(len(kin), len(forces))
    kin = kin.head(n)
    return Result(kin.mechanism, kin.engine, kin.t, {**kin.columns, **forces.head(n).columns}, kin.health, kin.meta)


def then_forces(
    solve: Callable[[Mechanism], Result], forces: Callable[[Mechanism, Result], ForceResult], mech: Mechanism
) -> Result:
    """Kinematics by ``solve``, then ``forces`` from them; a stopped run's partial Result gets its forces too."""
    try:
        res = solve(mech)
    except (MotionError, ValueError) as exc:
        part = getattr(exc, "partial", None)
        if isinstance(part, Result) and len(part):
            exc.partial = merge(part, forces(mech, part))  # type: ignore[attr-defined]
        raise
    return merge(res, forces(mech, res))


def unpack(solve: Callable[[Mechanism], tuple[Result, ForceResult]], mech: Mechanism) -> Result:
    """A (kinematics, forces) engine as one Result; its MotionError's (kinematics, forces) partial too."""
    try:
        kin, frc = solve(mech)
    except MotionError as exc:
        part: Any = exc.partial
        if isinstance(part, tuple):
            exc.partial = merge(*part)
        raise
    return merge(kin, frc)
