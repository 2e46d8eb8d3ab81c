"""vloop — kinematics of planar linkages by automatic vector loops.

mech = vloop.load("mechanisms/eightbar.toml")
res = vloop.solve(mech)            # times default to the file's [time]
res.link("l3").theta, res.slider("l4").v, res.point("C").ay
res.to_csv("results.csv")
forces = vloop.solve_forces(mech, res)  # with masses/loads in the file: torques, reactions [N, N·m]
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import MechanismError, MotionError, VloopError
from .mechanism import Mechanism, dumps, from_dict, load, loads, save
from .result import Result

__version__ = "0.1.0"

__all__ = [
    "Mechanism",
    "MechanismError",
    "MotionError",
    "Result",
    "VloopError",
    "__version__",
    "compile",
    "dumps",
    "from_dict",
    "load",
    "loads",
    "save",
    "solve",
    "solve_forces",
]


def compile(mechanism: Mechanism) -> Any:
    """Build the immutable LoopSystem (graph, loops, unknowns, blocks) of a mechanism."""
    from .loops import compile_system

    return compile_system(mechanism)


def solve(mechanism: Mechanism | Any, times: np.ndarray | None = None, **options: Any) -> Result:
    """Positions, velocities and accelerations over ``times`` (default: the file's [time]).

    ``mechanism`` may be a Mechanism or an already compiled LoopSystem.
    Options: ``method="auto"|"newton"``, ``tol``, ``max_iter``.
    Raises MotionError (with ``.partial``) if the motion cannot be completed.
    """
    from .solver import solve as _solve

    return _solve(mechanism, times, **options)


def solve_forces(mechanism: Mechanism | Any, result: Result) -> Any:
    """Driver torques [N·m] / forces [N], pin and slider reactions and the shaking force at every sample
    of ``result`` (a ForceResult; see :mod:`vloop.forces` for the columns and sign conventions)."""
    from .forces import solve_forces as _solve_forces

    return _solve_forces(mechanism, result)
