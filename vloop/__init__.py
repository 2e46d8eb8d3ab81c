"""vloop — kinematics of planar linkages by automatic vector loops.

    mech = vloop.load("mechanisms/eightbar.toml")
    res = vloop.solve(mech)            # times default to the file's [time]
    res.link("l3").theta, res.slider("l4").v, res.point("C").ay
    res.to_csv("results.csv")
    forces = vloop.solve_forces(mech, res)  # with masses/loads in the file: torques, reactions [N, N·m]

The teaching quantities (vloop.instant_centres, ...), vloop.study, vloop.simulate (forward dynamics) and
vloop.studio (the editor inline in a notebook: ``vloop.studio(mech)``) are imported on first use.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from .errors import MechanismError, MotionError, VloopError
from .mechanism import Mechanism, dumps, save
from .mechanism import from_dict as _read_dict
from .mechanism import load as _read_file
from .mechanism import loads as _read_text
from .model import SYSTEMS_KEY
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
    "dead_centres",
    "dumps",
    "from_dict",
    "instant_centres",
    "load",
    "loads",
    "mechanical_advantage",
    "save",
    "simulate",
    "solve",
    "solve_forces",
    "stroke",
    "studio",
    "study",
    "time_ratio",
    "transmission_angles",
    "velocity_ratio",
]

# teaching quantities (vloop.teaching), imported on first use to keep `import vloop` light
_TEACHING = (
    "dead_centres", "instant_centres", "mechanical_advantage", "stroke", "time_ratio", "transmission_angles",
    "velocity_ratio",
)  # fmt: skip


def __getattr__(name: str) -> Any:
    """The teaching functions, ``vloop.study``, ``vloop.simulate`` and every submodule (``vloop.teaching.cycle``
    after a plain ``import vloop``), imported on first use so that ``import vloop`` stays light. Imported by name:
    modules that import the package for vloop.solve must not look as if they depended on what is built on them."""
    import importlib
    import importlib.util

    if name in _TEACHING:
        return getattr(importlib.import_module(".teaching", __name__), name)
    if name == "study":
        return importlib.import_module(".studies.study", __name__).study
    if name == "simulate":
        return importlib.import_module(".dynamics.integrate", __name__).simulate
    if name == "studio":  # the package, callable: vloop.studio(mech) opens the notebook widget
        return importlib.import_module(".studio", __name__)
    if name.isidentifier() and not name.startswith("_") and importlib.util.find_spec(f"{__name__}.{name}"):
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'vloop' has no attribute {name!r}")


def load(path: str | Path, *, allow_external_profiles: bool = False) -> Mechanism:
    """Read and validate a mechanism file (:class:`MechanismError` on any problem); a file written from dimensions
    comes back assembled at t = 0 (docs/dimensions.md). Profiles must lie in the file's folder
    unless ``allow_external_profiles``."""
    return _assembled(_read_file(path, allow_external_profiles=allow_external_profiles))


def loads(
    text: str, *, source: str = "<string>", base_dir: str | Path | None = None, allow_external_profiles: bool = False
) -> Mechanism:
    """:func:`load` from TOML text."""
    return _assembled(
        _read_text(text, source=source, base_dir=base_dir, allow_external_profiles=allow_external_profiles)
    )


def from_dict(
    data: dict, *, source: str = "<dict>", base_dir: str | Path | None = None, allow_external_profiles: bool = False
) -> Mechanism:
    """:func:`load` from the parsed TOML structure."""
    return _assembled(
        _read_dict(data, source=source, base_dir=base_dir, allow_external_profiles=allow_external_profiles)
    )


def _assembled(mech: Mechanism) -> Mechanism:
    """A mechanism written from dimensions, assembled (its LoopSystem kept for the first solve); others as read."""
    if not mech.from_dimensions:
        return mech
    from .authoring import assemble_mechanism

    closed, report = assemble_mechanism(mech)
    _keep_system(closed, None, report.system)
    return closed


def compile(mechanism: Mechanism, method: str | None = None) -> Any:
    """Build the immutable LoopSystem (graph, loops, unknowns, blocks, t = 0 assembly) of a mechanism.

    ``method``: "auto" (closed-form dyads where possible) or "newton"; default: the file's [solver] method.
    """
    from .compiler import compile_system

    return compile_system(mechanism, method)


def solve(mechanism: Mechanism | Any, times: np.ndarray | None = None, **options: Any) -> Result:
    """Positions, velocities and accelerations over ``times`` [s] (default: the file's [time]).

    ``mechanism`` may be a Mechanism (compiled on the first solve, then kept with it) or a LoopSystem.
    Options: ``method="auto"|"newton"`` (a LoopSystem compiled otherwise keeps its variant), ``tol``,
    ``max_iter``, ``rtol``, ``memory_budget`` (bytes or "2G": a run whose results would not fit is refused,
    see vloop.files.budget). Raises MotionError (with ``.partial``) if the motion cannot be completed.
    """
    from .compiler import compile_system
    from .core.solver import solve as solve_system
    from .method.loops import LoopSystem

    method = options.pop("method", None)
    unknown = set(options) - {"tol", "max_iter", "rtol", "memory_budget"}
    if unknown:
        raise TypeError(f"unknown solver option(s): {', '.join(sorted(unknown))}")
    if isinstance(mechanism, LoopSystem):
        system = mechanism
        if method not in (None, mechanism.method):  # the other method's variant, compiled once per system
            key = f"method:{method}"
            if key not in mechanism.cache:
                mechanism.cache[key] = compile_system(mechanism.mechanism, method)
            system = mechanism.cache[key]
    else:
        system = _system_of(mechanism, method)
    return solve_system(system, times, **options)


def _system_of(mechanism: Mechanism, method: str | None) -> Any:
    """The LoopSystem of a Mechanism for ``method``, compiled once per (Mechanism object, method) and kept
    while that object lives (a Mechanism is immutable: solving it again needs no new compile)."""
    from .compiler import compile_system

    system = _systems(mechanism).get(method)
    if system is None:
        system = compile_system(mechanism, method)
        _keep_system(mechanism, method, system)
    return system


def _keep_system(mechanism: Mechanism, method: str | None, system: Any) -> None:
    """Keep ``system`` as the LoopSystem of ``mechanism`` for ``method`` while that object lives."""
    _systems(mechanism)[method] = system


def _systems(mechanism: Mechanism) -> dict[str | None, Any]:
    # on the object, like its cached views: the system refers back to the mechanism, and a cycle between the two
    # goes with them (a registry of its own would keep every mechanism ever solved)
    return mechanism.__dict__.setdefault(SYSTEMS_KEY, {})


def solve_forces(mechanism: Mechanism | Any, result: Result) -> Any:
    """Driver torques [N·m] / forces [N], pin and slider reactions and the shaking force at every sample
    of ``result`` (a ForceResult; see :mod:`vloop.forces` for the columns and sign conventions)."""
    from .forces import solve_forces as _solve_forces

    return _solve_forces(mechanism, result)
