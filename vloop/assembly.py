"""Assembly at t = 0: close the loops from the file's coordinates (drivers at their t = 0 values).

The typed coordinates may close the loops only approximately (rounded numbers, stated lengths,
a driver's theta0): within ``assembly_tolerance`` of the mechanism size they are assembled to full
precision by Newton (least squares on all loop equations) and the distance every joint moved is
reported; beyond it the file is refused, naming the loop and the closure error.
"""

from __future__ import annotations

import numpy as np

from .drivers import evaluate_all
from .errors import MechanismError
from .loops import LoopSystem, loop_jacobian, loop_residual, term_values

DEFAULT_ASSEMBLY_TOL = 1e-3  # t = 0 closure accepted up to this fraction of the mechanism size
SINGULAR_RCOND = 1e-10  # smallest/largest singular value below this: singular Jacobian


def assemble(sys: LoopSystem) -> tuple[np.ndarray, dict]:
    """Close the loops at t = 0 from the file's coordinates (drivers at their t = 0 values)."""
    mech = sys.mechanism
    tol = mech.options.get("assembly_tolerance", DEFAULT_ASSEMBLY_TOL)
    q = sys.coords_q.copy()
    if mech.drivers:
        x0 = evaluate_all(mech, np.zeros(1))[0][0]
        q[list(sys.drivers)] = x0
    scale = mech.scale
    if not sys.loops:
        return q, {"iterations": 0, "closure": 0.0, "moved": 0.0}
    res0 = np.abs(loop_residual(sys, q))
    worst = int(np.argmax(res0))
    if res0[worst] > tol * scale:
        lp = sys.loops[worst]
        why = ""
        if any(abs(q[v] - sys.coords_q[v]) > 1e-12 for v in sys.drivers):
            why = " with the drivers' t = 0 values (theta0/s0 differ from the coordinates)"
        raise MechanismError(
            f"{mech.source}: [joints] the t = 0 coordinates do not close loop {lp.index + 1} ({lp.label}){why}: "
            f"off by {res0[worst]:.4g} {mech.units} ({res0[worst] / scale:.2g} of the mechanism size; "
            f"accepted up to {tol:g})",
            entry="joints",
        )
    unk = list(sys.unknowns)
    rows = list(range(len(sys.loops)))
    it = 0
    for it in range(1, 51):  # noqa: B007 - iteration count is reported
        F = loop_residual(sys, q)
        Fr = np.concatenate([F.real, F.imag])
        J = loop_jacobian(sys, q, rows, unk)
        step = np.linalg.lstsq(J, -Fr, rcond=None)[0]
        q[unk] += step
        if np.max(np.abs(step), initial=0.0) <= 1e-14 * (1 + np.max(np.abs(q[unk]), initial=0.0)):
            break
    closure = float(np.max(np.abs(loop_residual(sys, q)))) / scale
    if closure > 1e-11:
        raise MechanismError(
            f"{mech.source}: [joints] cannot assemble the mechanism at t = 0 from the given coordinates "
            f"(closure {closure:.2g} of its size after {it} Newton steps)",
            entry="joints",
        )
    J = loop_jacobian(sys, q, rows, unk)
    if unk:
        sv = np.linalg.svd(J, compute_uv=False)
        if sv[-1] < SINGULAR_RCOND * sv[0]:
            raise MechanismError(
                f"{mech.source}: [joints] the loop Jacobian is singular at t = 0 "
                f"(rank {int(np.sum(sv >= SINGULAR_RCOND * sv[0]))} "
                f"of {len(unk)}): the mechanism is at a dead point or toggle at t = 0, or some of its constraints are "
                f"redundant; Gruebler's count M = {mech.gruebler()[2]} does not see this",
                entry="joints",
            )
    # how far the assembly moved each point from the typed coordinates
    z0 = term_values(sys, sys.coords_q)
    z1 = term_values(sys, q)
    moved = np.abs((z1 - z0) @ sys.path) if len(sys.point_names) else np.zeros(0)
    return q, {
        "iterations": it,
        "closure": closure,
        "initial_closure": float(res0.max()) / scale,
        "moved": float(moved.max(initial=0.0)),
        "moved_by_point": dict(zip(sys.point_names, moved.tolist(), strict=True)),
    }
