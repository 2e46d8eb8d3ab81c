"""Assembly at t = 0: close the loops from the file's coordinates (drivers at their t = 0 values).

The typed coordinates may close the loops only approximately (rounded numbers, stated lengths,
a driver's theta0): within ``assembly_tolerance`` of the mechanism size they are assembled to full
precision by Newton (least squares on all loop equations) and the distance every joint moved is
reported; beyond it the file is refused, naming the loop and the closure error.

The procedures only (Newton on a group or a dyad, the rank, how far joints moved, a group's assemblies from many
starts): the loop terms they evaluate are :mod:`vloop.method.loops`'.
"""

from __future__ import annotations

import math

import numpy as np

from ..drivers import evaluate
from ..errors import MechanismError
from ..model import Mechanism, mobility_message
from .loops import DyadTerms, LoopGroup, LoopSystem, TermIndex, loop_jacobian, term_values
from .structure import Structure

DEFAULT_ASSEMBLY_TOL = 1e-3  # t = 0 closure accepted up to this fraction of the mechanism size
CLOSED = 1e-11  # loops closed to this fraction of the mechanism's size count as assembled
SINGULAR_RCOND = 1e-10  # smallest/largest singular value below this: singular Jacobian


def assemble(system: LoopSystem, structure: Structure) -> tuple[np.ndarray, dict, np.ndarray | None]:
    """Close the loops at t = 0, group by group in solving order; check the rank (mobility) there.

    Returns the assembled variables, a report: Newton iterations, closure, how far the typed
    joints moved, and for a redundant linkage what is redundant (``report["redundancy"]``), and the
    term vectors there (None without loops).
    """
    mech = system.mechanism
    q = system.coords_q.copy()
    if mech.drivers:
        q[list(system.drivers)] = inputs_at_start(mech)
    if not system.loops:
        return q, {"iterations": 0, "closure": 0.0, "moved": 0.0}, None
    every = TermIndex(system)
    z_typed, e_typed = every.at(q)
    typed = np.array_equal(q, system.coords_q)  # no driver moved off its coordinates
    initial = _check_typed_closure(system, q, z_typed)
    groups: list[tuple[LoopGroup | DyadTerms, list[int]]] = []
    iterations = 0
    for loops, unknowns in structure.groups:
        if not unknowns:
            continue
        group: LoopGroup | DyadTerms | None = None
        steps = None
        if len(loops) == 1 and len(unknowns) == 2:
            group = DyadTerms(system, loops[0], list(unknowns))
            steps = _close_dyad(group, q)
        if steps is None:  # numpy's least squares; the first group starts from the typed q: its vectors are known
            group = LoopGroup(system, list(loops), list(unknowns))
            steps = _close(group, q, list(unknowns), (z_typed[group.k], e_typed[group.k]) if not groups else None)
        groups.append((group, list(unknowns)))
        iterations += steps
    z, e = every.at(q) if groups else (z_typed, e_typed)
    closure = float(np.abs(z @ system.C.T).max()) / mech.scale
    if closure > CLOSED:
        raise MechanismError(
            f"{mech.source}: [joints] cannot assemble the mechanism at t = 0 from the given coordinates "
            f"(closure {closure:.2g} of its size after {iterations} Newton steps){_over_note(system)}",
            entry="joints",
        )
    z0 = z_typed if typed else every.at(system.coords_q)[0]
    report = {"iterations": iterations, "closure": closure, "initial_closure": initial, **moved(system, q, z0, z)}
    for group, unknowns in groups:
        _check_rank(system, group.jacobian(z[group.k], e[group.k]), unknowns)
    if structure.over_determined:
        report["redundancy"] = redundancy(system, q)
    return q, report, z


def inputs_at_start(mech: Mechanism) -> list[float]:
    """The drivers' inputs at t = 0: x0 + v0·t + a0·t²/2 by drivers.evaluate's operations in the same order (the
    same bits, without its arrays), a profile by drivers.evaluate itself."""
    t = 0.0
    return [
        d.x0 + d.v0 * t + 0.5 * d.a0 * t * t if d.profile is None else float(evaluate(d, np.zeros(1))[0][0])
        for d in mech.drivers
    ]


def _check_typed_closure(system: LoopSystem, q: np.ndarray, z: np.ndarray) -> float:
    """The typed coordinates' closure (fraction of the size); refused beyond ``assembly_tolerance``. ``z``: the
    term vectors at ``q``."""
    mech = system.mechanism
    tol = mech.options.get("assembly_tolerance", DEFAULT_ASSEMBLY_TOL)
    res0 = np.abs(z @ system.C.T)
    worst = int(res0.argmax())
    if res0[worst] > tol * mech.scale:
        loop = system.loops[worst]
        why = ""
        if any(abs(q[v] - system.coords_q[v]) > 1e-12 for v in system.drivers):
            why = " with the drivers' t = 0 values (theta0/s0 differ from the coordinates)"
        raise MechanismError(
            f"{mech.source}: [joints] the t = 0 coordinates do not close loop {loop.index + 1} ({loop.label}){why}: "
            f"off by {res0[worst]:.4g} {mech.units} ({res0[worst] / mech.scale:.2g} of the mechanism size; "
            f"accepted up to {tol:g}){_over_note(system)}",
            entry="joints",
        )
    return float(res0.max()) / mech.scale


def _over_note(system: LoopSystem) -> str:
    """Where Gruebler's count is below the drivers, a failure to close says why it matters."""
    mech = system.mechanism
    M = mech.gruebler()[2]
    if M >= len(mech.drivers):
        return ""
    return (
        f" (Gruebler M = {M} with {len(mech.drivers)} driver{'s' if len(mech.drivers) != 1 else ''}: the linkage is "
        "over-constrained and can move only if its dimensions are exact)"
    )


def _close(g: LoopGroup, q: np.ndarray, unknowns: list[int], ze: tuple[np.ndarray, np.ndarray] | None = None) -> int:
    """Newton (least squares) on the group's loops for ``unknowns``, the other variables held; returns the
    iterations. ``ze``: the group's term vectors and directions at ``q``, where known."""
    for it in range(1, 51):
        zk, ek = g.at(q) if ze is None or it > 1 else ze
        F = g.residual(zk)
        J = g.jacobian(zk, ek)
        rhs = -np.concatenate((F.real, F.imag))
        try:  # a square group: a plain solve (least squares only for redundant or singular groups)
            step = np.linalg.solve(J, rhs) if J.shape[0] == J.shape[1] else np.linalg.lstsq(J, rhs, rcond=None)[0]
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(J, rhs, rcond=None)[0]
        dq = step.tolist()
        for v, d in zip(unknowns, dq, strict=True):
            q[v] += d
        if _max_abs(dq) <= 1e-14 * (1 + _max_abs(q[unknowns].tolist())):
            return it
    return 50


def _close_dyad(dyad: DyadTerms, q: np.ndarray) -> int | None:
    """Newton on one loop in two unknowns from q (written into q), in Python numbers (numpy's calls cost more than
    the arithmetic of a few terms): the same steps as :func:`_close` on its LoopGroup, the 2×2 step by Cramer's rule;
    the iterations, or None (q untouched) where a step is singular or not finite or 50 do not converge: the caller
    then takes :func:`_close`'s least-squares path."""
    x = q.tolist()
    u0, u1 = dyad.unknowns
    for it in range(1, 51):
        z, e = dyad.at(x)
        F = sum(t[0] * zt for t, zt in zip(dyad.terms, z, strict=True))
        j0, j1 = dyad.columns(z, e)
        det = j0.real * j1.imag - j1.real * j0.imag
        if det == 0 or not math.isfinite(det):
            return None
        d0 = (j1.real * F.imag - j1.imag * F.real) / det  # J·d = −[Re F; Im F]
        d1 = (j0.imag * F.real - j0.real * F.imag) / det
        if not (math.isfinite(d0) and math.isfinite(d1)):
            return None
        x[u0] += d0
        x[u1] += d1
        if max(abs(d0), abs(d1)) <= 1e-14 * (1 + max(abs(x[u0]), abs(x[u1]))):
            q[u0], q[u1] = x[u0], x[u1]
            return it
    return None


def close_group(system: LoopSystem, loops: list[int], unknowns: list[int], q: np.ndarray) -> bool:
    """Close ``loops`` for ``unknowns`` from ``q`` (written into it), the other variables held, by the same Newton
    as the assembly's; whether they close to 1e-11 of the mechanism's size."""
    g = LoopGroup(system, loops, unknowns)
    _close(g, q, unknowns)
    F = np.abs(g.residual(g.at(q)[0]))
    return bool(np.all(np.isfinite(F)) and F.max(initial=0.0) <= CLOSED * system.mechanism.scale)


STARTS = 512  # random starts besides the given one, for the assemblies of a group (seeded: the same every time)


def assemblies(system: LoopSystem, loops: list[int], unknowns: list[int], q: np.ndarray) -> list[np.ndarray]:
    """The assemblies of ``loops`` in ``unknowns`` (the other variables as in ``q``) that Newton finds from ``q`` and
    from :data:`STARTS` seeded random starts (angles uniform over a turn, slides within twice the size of ``q``'s):
    every configuration closed to 1e-11 of the size, each once (angles compared modulo 2π, to 1e-7), the one
    reached from ``q`` first where it closes. Newton from many starts is not a proof that none is missed."""
    mech, n_angles = system.mechanism, system.n_angles
    cols = np.asarray(unknowns)
    rng = np.random.default_rng(0)
    starts = np.repeat(q[None, :], STARTS + 1, axis=0)
    angle = cols < n_angles
    starts[1:, cols[angle]] = rng.uniform(-math.pi, math.pi, (STARTS, int(angle.sum())))
    slides = cols[~angle]
    starts[1:, slides] = q[slides] + rng.uniform(-2, 2, (STARTS, len(slides))) * mech.scale
    near = _newton_many(system, loops, cols, starts)
    distinct: list[np.ndarray] = []
    for row in near:
        diff = row[cols] - np.array([d[cols] for d in distinct]).reshape(-1, len(cols))
        diff[:, angle] = np.angle(np.exp(1j * diff[:, angle]))
        diff[:, ~angle] /= mech.scale
        if not np.any(np.all(np.abs(diff) <= 1e-7, axis=1)):
            distinct.append(row)
    return [row for row in distinct if close_group(system, loops, list(cols), row)]  # polished in place


def _newton_many(system: LoopSystem, loops: list[int], cols: np.ndarray, rows: np.ndarray) -> list[np.ndarray]:
    """Newton (60 steps, each angle's step limited to 1 rad) on ``loops`` for the variables ``cols`` from every row
    of ``rows`` at once: the rows it closed to 1e-9 of the size, in their order."""
    group = LoopGroup(system, loops, list(cols))
    turns = cols < system.n_angles
    q = rows.copy()
    active = np.arange(len(q))  # rows still stepping (a row whose step is below 1e-13 of a unit has converged)
    for _ in range(60):
        F, J = group.many(q[active])
        step = np.einsum("ncr,nr->nc", np.linalg.pinv(J), -np.concatenate((F.real, F.imag), axis=1))
        step[:, turns] = np.clip(step[:, turns], -1.0, 1.0)
        step = np.where(np.isfinite(step), step, 0.0)
        q[np.ix_(active, cols)] += step
        active = active[
            np.abs(step).max(axis=1, initial=0.0) > 1e-13 * (1 + np.abs(q[np.ix_(active, cols)]).max(axis=1))
        ]
        if not len(active):
            break
    F = np.abs(group.many(q)[0]).max(axis=1)
    return [row for row, f in zip(q, F, strict=True) if f <= 1e-9 * system.mechanism.scale]


def _max_abs(xs: list[float]) -> float:
    """max |x| (nan if any x is nan, as numpy's max), for the few numbers of a group."""
    m = max(map(abs, xs))
    return m if all(x == x for x in xs) else math.nan


def _check_rank(system: LoopSystem, J: np.ndarray, unknowns: list[int]) -> None:
    """A group's Jacobian ``J`` (in ``unknowns``) must have full column rank at t = 0 (else a dead point or
    toggle): its singular values' ratio at least SINGULAR_RCOND."""
    if J.shape == (2, 2) and _clearly_regular(J):
        return
    sv = np.linalg.svd(J, compute_uv=False)
    if sv[-1] < SINGULAR_RCOND * sv[0]:
        mech = system.mechanism
        raise MechanismError(
            f"{mech.source}: [joints] the loop Jacobian is singular at t = 0 "
            f"(rank {int(np.sum(sv >= SINGULAR_RCOND * sv[0]))} of {len(unknowns)}): the mechanism is at a dead "
            f"point or toggle at t = 0, or some of its constraints are redundant; Gruebler's count "
            f"M = {mech.gruebler()[2]} does not see this",
            entry="joints",
        )


EPS = float(np.finfo(float).eps)


def _clearly_regular(J: np.ndarray) -> bool:
    """Whether a 2×2 matrix's singular values σ₂ ≤ σ₁ certainly have σ₂/σ₁ > 100·SINGULAR_RCOND, so that the SVD's
    rank test passes (its computed values are within a few ε·σ₁): σ₁σ₂ = |det| and σ₁² ≤ ‖J‖²_F give
    σ₂/σ₁ ≥ |det|/‖J‖²_F, with det's and the norm's rounding bounded. Overflow, underflow or nan: False (the SVD
    decides)."""
    (a, b), (c, d) = J.tolist()
    ad, bc = a * d, b * c
    det_low = abs(ad - bc) - 4 * EPS * (abs(ad) + abs(bc))
    return det_low > 100 * SINGULAR_RCOND * (1 + 8 * EPS) * (a * a + b * b + c * c + d * d)


def redundancy(system: LoopSystem, q: np.ndarray) -> dict:
    """Mobility from the rank of the full loop Jacobian (all variables, driven ones included) at ``q``.

    Gruebler's count below the number of drivers is then either a redundant linkage — the rank leaves
    exactly as many freedoms as drivers (it moves, but only because its dimensions are exact) — or a
    structure that cannot move (raised here). Returns the rank, the equations and the loops whose
    equations are redundant (the rows a pivoted QR leaves out).
    """
    import scipy.linalg

    mech = system.mechanism
    rows = list(range(len(system.loops)))
    n_vars = system.n_vars
    J = loop_jacobian(system, q, rows, list(range(n_vars)))
    sv = np.linalg.svd(J, compute_uv=False)
    rank = int(np.sum(sv >= SINGULAR_RCOND * sv[0])) if len(sv) else 0
    mobility = n_vars - rank
    M = mech.gruebler()[2]
    if mobility != len(mech.drivers):
        raise MechanismError(
            mobility_message(
                mech, f" (the loop Jacobian at t = 0 has rank {rank} of {n_vars} variables: actual mobility {mobility})"
            ),
            entry="drivers",
        )
    _, _, piv = scipy.linalg.qr(J.T, pivoting=True)  # independent equations first
    dependent = sorted({int(r) % len(system.loops) for r in piv[rank:]})
    return {
        "gruebler": M,
        "mobility": mobility,
        "equations": 2 * len(system.loops),
        "rank": rank,
        "redundant_equations": 2 * len(system.loops) - rank,
        "loops": [li + 1 for li in dependent],
    }


def redundancy_text(info: dict, system: LoopSystem) -> str:
    """The one line vloop prints for a redundant linkage."""
    where = ", ".join(f"{n} ({system.loops[n - 1].label})" for n in info["loops"])
    return (
        f"redundant constraint in loop {where}: Gruebler M = {info['gruebler']}, actual mobility {info['mobility']} "
        f"(loop Jacobian rank {info['rank']} of {info['equations']} equations): it moves only because its "
        "dimensions are exact; its reactions are statically indeterminate"
    )


def moved(system: LoopSystem, q: np.ndarray, z0: np.ndarray | None = None, z1: np.ndarray | None = None) -> dict:
    """How far the assembly at ``q`` moved each point from the typed coordinates (``z0``, ``z1``: the term vectors
    at the typed coordinates and at ``q``, where known)."""
    z0 = term_values(system, system.coords_q) if z0 is None else z0
    z1 = term_values(system, q) if z1 is None else z1
    dist = np.abs((z1 - z0) @ system.path) if len(system.point_names) else np.zeros(0)
    return {
        "moved": float(dist.max(initial=0.0)),
        "moved_by_point": dict(zip(system.point_names, dist.tolist(), strict=True)),
    }
