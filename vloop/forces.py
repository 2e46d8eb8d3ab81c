"""Kinetostatics: driver torques, joint reactions and the shaking force from the solved kinematics.

    forces = vloop.solve_forces(mech, vloop.solve(mech))
    forces["l2.torque"], forces.pin("B", on="l5").mag, forces.shaking.fx, forces.to_csv("forces.csv")

Newton–Euler for every moving body (links and slider blocks), about its centre of mass G:

    Σ F = m·a_G,        Σ M_G = I_G·α            (SI units: N, N·m, kg, kg·m², m/s²)

with gravity, the file's loads and these unknowns (the columns of ``forces.csv``):

* ``LINK.torque`` [N·m] — a crank driver's torque, applied by the ground to the driven link, CCW
  positive (the ground takes −τ); ``SLIDER.force`` [N] — a driven slider's force along its axis
  u, applied by the guide to the block at the slider joint (the guide takes −f·u);
* ``JOINT:FROM>ON.fx|fy|mag`` [N, world frame] — the force body FROM exerts on body ON through the
  pin at JOINT. A pin joining bodies B0 … Bk is modelled as carried by one of them — the ground if
  the ground is one of them, else the first listed (links in file order, then slider blocks) — and
  reports the force the carrier exerts on every other body (the carrier takes the opposite of their
  sum). A two-body pin is the textbook F_ij, the force of i on j;
* ``SLIDER.normal`` [N] — the guide's force on the block at the slider joint P along the axis's left
  normal n = k × u; ``SLIDER.moment`` [N·m] — the guide's moment on the block about P, CCW;
* ``shaking.fx|fy`` [N], ``shaking.moment`` [N·m] — everything the moving parts exert on the ground
  through its pins, guides and drivers (the drivers' reaction torques included), the moment taken
  about the world origin. With gravity this includes the weight; without it, it is the textbook
  inertial shaking force −Σ m·a_G.

The equations are linear in the unknowns and their matrix depends on positions only, so its
sparsity is fixed: :func:`compile_forces` builds the index arrays once and orders the equations
block-triangularly (a maximum matching and the strongly connected components, as for the loop
equations); :func:`solve_forces` fills every sample's coefficients at once and solves the small
diagonal blocks for all samples together. A non-square or structurally deficient system (redundant
constraints: an over-constrained linkage) is solved by least squares instead, and every reaction
that the equations leave free is listed in ``ForceResult.indeterminate`` with no number.

Lengths come from the Result in the file's ``units`` and are converted to metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np

from .errors import VloopError
from .model import Load, Mechanism, length_factor
from .result import Result

SHAKING = "shaking"
RANK_TOL = 1e-9  # singular values below this fraction of the largest count as zero (redundant path)


class ForceError(VloopError):
    """The forces cannot be computed (missing kinematics, a non-finite value, unbalanced loads)."""


def has_forces(mech: Mechanism) -> bool:
    """True when the mechanism states any mass, inertia or load (then ``vloop run`` writes forces.csv)."""
    return bool(mech.masses or mech.loads)


def pin_carrier(mech: Mechanism, joint: str) -> str:
    """The body a pin is modelled as carried by: the ground if it is at the pin, else the first listed."""
    bodies = mech.bodies_at(joint)
    return mech.ground if mech.ground in bodies else bodies[0]


def reaction_names(mech: Mechanism) -> list[tuple[str, str, str]]:
    """Every pin connection as (joint, from, on), in joint order."""
    out = []
    for j in mech.joints:
        bodies = mech.bodies_at(j)
        if len(bodies) >= 2:
            c = pin_carrier(mech, j)
            out += [(j, c, b) for b in bodies if b != c]
    return out


def body_com(mech: Mechanism, body: str) -> tuple[float, float]:
    """Centre of mass in the body frame [file units]: the file's ``com`` (world, t = 0) carried into
    the frame, or the mean of the body's joints in the frame for a massless body."""
    b = mech.bodies()[body]
    mp = mech.masses.get(body)
    if mp is None:
        pts = [b.local[j] for j in b.joints]
        return (sum(p[0] for p in pts) / len(pts), sum(p[1] for p in pts) / len(pts))
    c, s = math.cos(b.theta0), math.sin(b.theta0)
    dx, dy = mp.com[0] - b.origin[0], mp.com[1] - b.origin[1]
    return (c * dx + s * dy, -s * dx + c * dy)


def load_values(load: Load, t: np.ndarray) -> np.ndarray:
    """A load over times ``t`` [s]: (n, 2) force [N] or (n,) torque [N·m]; a profile is interpolated
    linearly between its rows (MechanismError-style ForceError outside its time range)."""
    t = np.asarray(t, float)
    p = load.profile
    if p is None:
        return np.broadcast_to(np.asarray(load.value, float), (len(t), 2) if load.kind == "force" else (len(t),))
    span = p.t[-1] - p.t[0]
    bad = (t < p.t[0] - 1e-12 * span) | (t > p.t[-1] + 1e-12 * span)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise ForceError(
            f"[{load.entry}] time t = {t[k]:g} s is outside the load profile's range [{p.t[0]:g}, {p.t[-1]:g}] s",
            entry=load.entry,
            time=float(t[k]),
            sample=k,
        )
    cols = [np.interp(t, p.t, p.values[:, i]) for i in range(p.values.shape[1])]
    return np.column_stack(cols) if load.kind == "force" else cols[0]


# ---------------------------------------------------------------- the compiled model


@dataclass(frozen=True)
class Effect:
    """How one unknown acts on one body: a force sign·x·dir at point ``point``, or a couple sign·x."""

    unknown: int
    body: int  # index into ForceModel.bodies, −1 for the ground
    sign: float
    direction: int  # index into the direction table, −1 for a couple
    point: str | None


@dataclass(frozen=True)
class ForceModel:
    """Index arrays of the kinetostatic equations of one mechanism (built once; positions fill them).

    Equation rows: 3 per moving body (x, y, moment about G). ``blocks``: (rows, cols) index arrays
    of the diagonal blocks in solving order (``None`` when the system is not square and structurally
    regular: then it is solved by least squares). ``directions``: ``"x"``, ``"y"``, or
    ``("u"|"n", slider)``.
    """

    mechanism: Mechanism
    bodies: tuple[str, ...]
    unknowns: tuple[str, ...]
    effects: tuple[Effect, ...]
    directions: tuple[Any, ...]
    mass: np.ndarray
    inertia: np.ndarray
    com: np.ndarray  # (n_bodies, 2) body frame [m]
    entries: dict[str, np.ndarray]  # row, col, kind (0 x, 1 y, 2 moment of a force, 3 couple), sign, dir, app
    apps: tuple[tuple[str, int], ...]  # (point, body) pairs whose arm r_point − r_G the moments use
    blocks: tuple[tuple[np.ndarray, np.ndarray], ...] | None
    factor: float  # metres per file length unit
    origins: tuple[str, ...] = ()  # per body: the joint at its frame origin
    # per body, how its frame's x axis is found: (first joint, second joint, their distance) for a link,
    # (joint, None, fixed angle) for a block on a ground guide, (joint, None, None) when θ must be used
    axes: tuple[tuple[str, str | None, float | None], ...] = ()
    plans: tuple[dict[str, Any], ...] = ()  # per block: how to assemble and solve it (_block_plans)

    @property
    def n_eq(self) -> int:
        return 3 * len(self.bodies)


def compile_forces(mech: Mechanism) -> ForceModel:
    """The index arrays and block order of ``mech``'s kinetostatic equations (see the module notes)."""
    try:
        factor = length_factor(mech.units)
    except KeyError:
        raise ForceError(f"{mech.name}: forces need a known length unit, got {mech.units!r}", entry="units") from None
    bodies = tuple(mech.moving_links)
    index = {b: i for i, b in enumerate(bodies)}
    index[mech.ground] = -1
    unknowns, effects, directions = _unknowns(mech, index)
    com = np.array([body_com(mech, b) for b in bodies], float).reshape(-1, 2) * factor
    mass = np.array([mech.masses[b].mass if b in mech.masses else 0.0 for b in bodies])
    inertia = np.array([mech.masses[b].inertia if b in mech.masses else 0.0 for b in bodies])
    entries, apps = _entries(mech, bodies, effects, directions, com / factor)
    blocks = _block_order(3 * len(bodies), len(unknowns), entries["row"], entries["col"])
    frames = mech.bodies()
    origins = tuple(frames[b].joints[0] for b in bodies)
    return ForceModel(
        mech, bodies, tuple(unknowns), tuple(effects), tuple(directions), mass, inertia, com, entries, apps, blocks,
        factor, origins, tuple(_frame_axis(mech, frames[b]) for b in bodies), _block_plans(entries, blocks),
    )  # fmt: skip


def _frame_axis(mech: Mechanism, body: Any) -> tuple[str, str | None, float | None]:
    """How a body frame's x axis is found over the samples (see ForceModel.axes)."""
    if body.kind == "link" and len(body.joints) >= 2:
        return body.joints[0], body.joints[1], body.local[body.joints[1]][0]
    if body.kind == "block" and mech.links[body.guide].ground:
        return body.joints[0], None, body.theta0
    return body.joints[0], None, None


def _unknowns(mech: Mechanism, index: dict[str, int]) -> tuple[list[str], list[Effect], list[Any]]:
    """Unknown scalars (named as their output columns) and how each acts on the bodies."""
    unknowns: list[str] = []
    effects: list[Effect] = []
    directions: list[Any] = ["x", "y"]

    def add(name: str) -> int:
        unknowns.append(name)
        return len(unknowns) - 1

    for j, c, b in reaction_names(mech):
        for d, comp in enumerate(("fx", "fy")):
            k = add(f"{j}:{c}>{b}.{comp}")
            effects += [Effect(k, index[b], 1.0, d, j), Effect(k, index[c], -1.0, d, j)]
    slider_dir = {}
    for s in mech.sliders.values():
        slider_dir[s.name] = len(directions)
        directions += [("u", s.name), ("n", s.name)]
        block, guide = index[s.name], index[s.guide]
        k = add(f"{s.name}.normal")
        effects += [
            Effect(k, block, 1.0, slider_dir[s.name] + 1, s.joint),
            Effect(k, guide, -1.0, slider_dir[s.name] + 1, s.joint),
        ]
        k = add(f"{s.name}.moment")
        effects += [Effect(k, block, 1.0, -1, None), Effect(k, guide, -1.0, -1, None)]
    for d in mech.drivers:
        if d.kind == "crank":
            k = add(f"{d.target}.torque")
            effects += [Effect(k, index[d.target], 1.0, -1, None), Effect(k, -1, -1.0, -1, None)]
        else:
            s = mech.sliders[d.target]
            k = add(f"{s.name}.force")
            u = slider_dir[s.name]
            effects += [Effect(k, index[s.name], 1.0, u, s.joint), Effect(k, index[s.guide], -1.0, u, s.joint)]
    return unknowns, effects, directions


def _entries(
    mech: Mechanism, bodies: tuple[str, ...], effects: list[Effect], directions: list[Any], com: np.ndarray
) -> tuple[dict[str, np.ndarray], tuple[tuple[str, int], ...]]:
    """The structurally nonzero coefficients: one per (effect, equation row) that can be nonzero.

    Structural zeros are decided from the geometry, never from values: a world x/y direction has no
    y/x component; a slider axis on a ground guide is constant, so its zero components stay zero;
    a force through the body's centre of mass has no moment; the slider's own directions are fixed in
    the block frame, so their moment on the block is constant.
    """
    frames = mech.bodies()
    apps: dict[tuple[str, int], int] = {}
    rows, cols, kinds, signs, dirs, arms = [], [], [], [], [], []

    def entry(row: int, e: Effect, kind: int, arm: int = -1) -> None:
        values = (row, e.unknown, kind, e.sign, e.direction, arm)
        for lst, v in zip((rows, cols, kinds, signs, dirs, arms), values, strict=True):
            lst.append(v)

    for e in effects:
        if e.body < 0:
            continue
        r0 = 3 * e.body
        if e.direction < 0:
            entry(r0 + 2, e, 3)
            continue
        d = directions[e.direction]
        const = _constant_direction(mech, d)
        for axis in (0, 1):
            if const is None or const[axis] != 0.0:
                entry(r0 + axis, e, axis)
        local = frames[bodies[e.body]].local.get(e.point)  # None: the point slides along this body (a guide)
        if local is not None:
            arm_local = np.subtract(local, com[e.body])
            fixed = _direction_in_body(mech, d, bodies[e.body])
            if not np.any(arm_local):
                continue  # through G
            if fixed is not None and arm_local[0] * fixed[1] - arm_local[1] * fixed[0] == 0.0:
                continue  # along a line through G, fixed in the body
        key = (e.point, e.body)
        apps.setdefault(key, len(apps))
        entry(r0 + 2, e, 2, apps[key])
    arr = {
        "row": np.array(rows, int),
        "col": np.array(cols, int),
        "kind": np.array(kinds, int),
        "sign": np.array(signs, float),
        "dir": np.array(dirs, int),
        "app": np.array(arms, int),
    }
    arr.update(_entry_kinds(mech, arr, directions))
    return arr, tuple(apps)


def _entry_kinds(mech: Mechanism, e: dict[str, np.ndarray], directions: list[Any]) -> dict[str, np.ndarray]:
    """Split the coefficients by how they are evaluated (see :func:`_coefficients`)."""
    const: dict[int, float] = {}  # entry -> its value
    arm: dict[int, tuple[float, int]] = {}  # entry -> (coefficient, arm component)
    turning, cross = [], []
    for i, (kind, d, sign) in enumerate(zip(e["kind"], e["dir"], e["sign"], strict=True)):
        c = _constant_direction(mech, directions[d]) if kind in (0, 1) else None
        if kind == 3:
            const[i] = sign
        elif kind in (0, 1) and c is not None:
            const[i] = sign * c[kind]
        elif kind in (0, 1):
            turning.append(i)
        elif directions[d] in ("x", "y"):  # moment of a world x / y force: −Δy·Fx, +Δx·Fy
            arm[i] = (-sign, 1) if directions[d] == "x" else (sign, 0)
        else:
            cross.append(i)
    const_idx, arm_idx = list(const), list(arm)
    variable = arm_idx + turning + cross
    var_row = np.full(len(e["kind"]), -1, int)  # row in the variable-coefficient table (_coefficients)
    var_row[np.array(variable, int)] = np.arange(len(variable))
    fixed = np.zeros(len(e["kind"]))
    fixed[np.array(const_idx, int)] = list(const.values())
    return {
        "var_row": var_row,
        "fixed": fixed,
        "const": np.array(const_idx, int),
        "const_value": np.array(list(const.values()), float),
        "arm": np.array(arm_idx, int),
        "arm_coef": np.array([a for a, _ in arm.values()], float),
        "arm_comp": np.array([k for _, k in arm.values()], int),
        "turning": np.array(turning, int),
        "cross": np.array(cross, int),
    }


def _constant_direction(mech: Mechanism, d: Any) -> tuple[float, float] | None:
    """World components of a direction that never turns (x, y, a ground slider's axis/normal)."""
    if d == "x":
        return (1.0, 0.0)
    if d == "y":
        return (0.0, 1.0)
    kind, name = d
    s = mech.sliders[name]
    if not mech.links.get(s.guide, None) or not mech.links[s.guide].ground:
        return None
    ux, uy = s.axis
    return (ux, uy) if kind == "u" else (-uy + 0.0, ux)


def _direction_in_body(mech: Mechanism, d: Any, body: str) -> tuple[float, float] | None:
    """A slider's u or n in the block's own frame (its x axis is u); None for other bodies/directions."""
    if isinstance(d, tuple) and d[1] == body:
        return (1.0, 0.0) if d[0] == "u" else (0.0, 1.0)
    return None


def _block_order(n_eq: int, n_unknowns: int, rows: np.ndarray, cols: np.ndarray) -> tuple | None:
    """Diagonal blocks (rows, cols) in solving order, or None if the pattern has no perfect matching."""
    if n_eq != n_unknowns or n_eq == 0:
        return None
    import networkx as nx
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import maximum_bipartite_matching

    pattern = csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_eq, n_unknowns))
    match = maximum_bipartite_matching(pattern, perm_type="column")  # row -> its matched unknown
    if np.any(match < 0):
        return None
    row_of = np.empty(n_unknowns, int)
    row_of[match] = np.arange(n_eq)
    g = nx.DiGraph()
    g.add_nodes_from(range(n_unknowns))
    g.add_edges_from((int(match[r]), int(c)) for r, c in zip(rows, cols, strict=True) if match[r] != c)
    cond = nx.condensation(g)
    order = list(nx.topological_sort(cond))[::-1]  # an unknown's equation needs what it points to: sinks first
    blocks = []
    for node in order:
        members = np.array(sorted(cond.nodes[node]["members"]), int)
        blocks.append((row_of[members], members))
    return tuple(blocks)


def _block_plans(entries: dict[str, np.ndarray], blocks: tuple | None) -> tuple[dict[str, Any], ...]:
    """Per diagonal block: its constant coefficients as a matrix, its variable ones as (row, col, table row),
    and its coupling to the unknowns solved before it (a constant matrix and variable terms)."""
    if blocks is None:
        return ()
    plans = []
    solved = np.zeros(entries["col"].max(initial=-1) + 1, bool)
    var_row, fixed = entries["var_row"], entries["fixed"]
    for rows, cols in blocks:
        r_local = {int(r): i for i, r in enumerate(rows)}
        c_local = {int(c): i for i, c in enumerate(cols)}
        mine = np.isin(entries["row"], rows)
        inner = np.nonzero(mine & np.isin(entries["col"], cols))[0]
        coupling = np.nonzero(mine & solved[entries["col"]])[0]
        k = len(rows)
        a_const = np.zeros((k, k))
        inner_var = []
        for e in inner:
            r, c = r_local[int(entries["row"][e])], c_local[int(entries["col"][e])]
            if var_row[e] < 0:
                a_const[r, c] = fixed[e]
            else:
                inner_var.append((r, c, int(var_row[e])))
        const_cols = sorted({int(entries["col"][e]) for e in coupling if var_row[e] < 0})
        c_const = np.zeros((k, len(const_cols)))
        var_terms = [e for e in coupling if var_row[e] >= 0]
        spread = np.zeros((k, len(var_terms)))
        for e in coupling:
            if var_row[e] < 0:
                c_const[r_local[int(entries["row"][e])], const_cols.index(int(entries["col"][e]))] += fixed[e]
        for i, e in enumerate(var_terms):
            spread[r_local[int(entries["row"][e])], i] = 1.0
        plans.append(
            {
                "rows": rows,
                "cols": cols,
                "a_const": a_const,
                "inner_var": inner_var,
                "const_cols": np.array(const_cols, int),
                "c_const": c_const,
                "var_rows": var_row[np.array(var_terms, int)],
                "var_cols": entries["col"][np.array(var_terms, int)],
                "spread": spread,
            }
        )
        solved[cols] = True
    return tuple(plans)


# ---------------------------------------------------------------- results


@dataclass
class ForceResult:
    """Force histories of one run. ``columns`` maps names (module notes) to arrays over ``t`` [N, N·m].

    ``indeterminate`` names the reactions the equations leave free (redundant constraints): they have
    no column; ``message`` says why. ``arrows`` lists (point, fx column, fy column, label) for drawing
    every pin reaction at its joint.
    """

    mechanism: str
    engine: str
    t: np.ndarray
    columns: dict[str, np.ndarray]
    indeterminate: list[str] = field(default_factory=list)
    message: str = ""
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t)

    def __getitem__(self, key: str) -> np.ndarray:
        return self.t if key == "t" else self.columns[key]

    def __contains__(self, key: str) -> bool:
        return key == "t" or key in self.columns

    @property
    def arrows(self) -> list[tuple[str, str, str, str]]:
        out = []
        for c in self.columns:
            if c.endswith(".fx") and ":" in c and ">" in c:
                base = c[:-3]
                joint, pair = base.split(":", 1)
                frm, on = pair.split(">", 1)
                out.append((joint, f"{base}.fx", f"{base}.fy", f"{frm}→{on} at {joint}"))
        return out

    def driver(self, name: str) -> np.ndarray:
        """A driver's torque [N·m] (crank ``name``) or force [N] (driven slider ``name``)."""
        for key in (f"{name}.torque", f"{name}.force"):
            if key in self.columns:
                return self.columns[key]
        raise KeyError(f"no driver '{name}' in these forces")

    def pin(self, joint: str, on: str | None = None) -> SimpleNamespace:
        """The pin reaction at ``joint`` on body ``on`` (default: the only or first one): ``.fx .fy .mag``."""
        keys = [c[:-3] for c in self.columns if c.startswith(f"{joint}:") and c.endswith(".fx")]
        keys = [k for k in keys if on is None or k.endswith(f">{on}")]
        if not keys:
            what = f"{joint} on {on}" if on else joint
            free = [r for r in self.indeterminate if r.startswith(f"{joint}:")]
            raise KeyError(f"no pin reaction at {what}" + (f" (indeterminate: {', '.join(free)})" if free else ""))
        return SimpleNamespace(**{f: self.columns[f"{keys[0]}.{f}"] for f in ("fx", "fy", "mag")})

    def slider(self, name: str) -> SimpleNamespace:
        """A slider's ``.normal`` [N] and ``.moment`` [N·m] (guide on block, at the slider joint)."""
        return SimpleNamespace(normal=self.columns[f"{name}.normal"], moment=self.columns[f"{name}.moment"])

    @property
    def shaking(self) -> SimpleNamespace:
        """What the moving parts exert on the ground: ``.fx .fy`` [N], ``.moment`` [N·m] about the origin."""
        return SimpleNamespace(**{f: self.columns[f"{SHAKING}.{f}"] for f in ("fx", "fy", "moment")})

    def head(self, n: int) -> ForceResult:
        cols = {k: v[:n] for k, v in self.columns.items()}
        return ForceResult(self.mechanism, self.engine, self.t[:n], cols, list(self.indeterminate), self.message)

    def check_finite(self) -> None:
        """Raise ForceError naming the first non-finite quantity and its sample."""
        for name, arr in self.columns.items():
            bad = ~np.isfinite(arr)
            if np.any(bad):
                k = int(np.argmax(bad))
                raise ForceError(
                    f"{self.mechanism}: {name} is not finite at t = {self.t[k]:g} s (sample {k}): "
                    "masses, inertias or loads too large for floating point",
                    time=float(self.t[k]),
                    sample=k,
                )

    def to_csv(self, path: str | Path) -> Path:
        """Write ``t`` and every column (``%.17g``) atomically; only finite numbers (else ForceError)."""
        from .files.output import atomic_write

        self.check_finite()
        names = ["t", *self.columns]
        arr = np.column_stack([self.t, *self.columns.values()]) if len(self.t) else np.zeros((0, len(names)))
        with atomic_write(path) as fh:
            np.savetxt(fh, arr, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
        return Path(path)

    def to_dataframe(self) -> Any:
        import pandas as pd

        return pd.DataFrame({"t": self.t, **self.columns})

    def as_result(self) -> Result:
        """The columns as a :class:`~vloop.result.Result` (for :func:`vloop.compare.compare`)."""
        return Result(self.mechanism, self.engine, self.t, dict(self.columns))


# ---------------------------------------------------------------- solving


def solve_forces(mech_or_system: Any, result: Result, *, model: ForceModel | None = None) -> ForceResult:
    """Driver torques/forces [N·m, N], pin and slider reactions and the shaking force [N, N·m] at every
    sample of ``result`` (positions, velocities, accelerations of the mechanism's links, joints, sliders)."""
    mech = mech_or_system if isinstance(mech_or_system, Mechanism) else mech_or_system.mechanism
    model = model if model is not None else compile_forces(mech)
    t = np.asarray(result.t, float)
    with np.errstate(all="ignore"):  # an overflow shows as a non-finite value: check_finite names it
        kin = _kinematics(model, result)
        values = _coefficients(model, kin)
        rhs = _right_hand_side(model, kin, t)
        x = _solve_blocks(model, values, rhs) if model.blocks is not None else None
        if x is not None and np.all(np.isfinite(x)):
            free, message = np.zeros(len(model.unknowns), bool), ""
        elif np.all(np.isfinite(rhs)):  # redundant, or a block singular at some sample: least squares says which
            x, free, message = _solve_least_squares(model, values, rhs)
        else:
            x, free, message = np.full((len(model.unknowns), len(t)), np.nan), np.zeros(len(model.unknowns), bool), ""
        columns = _columns(model, kin, x, free)
    out = ForceResult(mech.name, result.engine, t, columns, message=message)
    out.indeterminate = sorted({u.rsplit(".", 1)[0] for u, f in zip(model.unknowns, free, strict=True) if f})
    out.meta = {"units": {"force": "N", "moment": "N·m"}, "kinematics": result.engine}
    out.check_finite()
    return out


def _kinematics(model: ForceModel, result: Result) -> dict[str, Any]:
    """Per body (rows: bodies × samples): θ, ω, α, the centre of mass G and its acceleration; the moment
    arms r_P − r_G of the application points; the positions of the points the ground and the loads
    act at; the slider directions [SI]. One row at a time: every step is a few passes over the samples."""
    mech, f, n = model.mechanism, model.factor, len(result.t)

    def col(name: str, scale: float = 1.0) -> np.ndarray:
        try:
            arr = np.asarray(result[name], float)
        except KeyError:
            raise ForceError(f"{mech.name}: the kinematics have no column '{name}' (forces need it)") from None
        return arr * scale if scale != 1.0 else arr

    nb = len(model.bodies)
    kin: dict[str, Any] = {"n": n}
    for key in ("theta", "omega", "alpha", "gx", "gy", "agx", "agy"):
        kin[key] = np.empty((nb, n))
    for i, b in enumerate(model.bodies):
        th, om, al = col(f"{b}.theta"), col(f"{b}.omega"), col(f"{b}.alpha")
        kin["theta"][i], kin["omega"][i], kin["alpha"][i] = th, om, al
        o = model.origins[i]
        cx, cy = model.com[i]
        gx, gy, agx, agy = col(f"{o}.x", f), col(f"{o}.y", f), col(f"{o}.ax", f), col(f"{o}.ay", f)
        if cx or cy:  # G = O + R(θ)·c, a_G = a_O + α k × r − ω² r
            c, s = _unit(model, i, th, col)
            rx = c * cx - s * cy if cy else c * cx
            ry = s * cx + c * cy if cy else s * cx
            om2 = om * om
            gx, gy = gx + rx, gy + ry
            agx, agy = agx - al * ry - om2 * rx, agy + al * rx - om2 * ry
        kin["gx"][i], kin["gy"][i], kin["agx"][i], kin["agy"][i] = gx, gy, agx, agy
    arms = np.empty((len(model.apps), 2, n))
    for k, (p, b) in enumerate(model.apps):
        arms[k, 0] = col(f"{p}.x", f) - kin["gx"][b]
        arms[k, 1] = col(f"{p}.y", f) - kin["gy"][b]
    kin["arms"] = arms
    ground_points = {e.point for e in model.effects if e.body < 0 and e.point} | {
        ld.point for ld in mech.loads if ld.point
    }
    kin["points"] = {p: (col(f"{p}.x", f), col(f"{p}.y", f)) for p in ground_points}
    kin["directions"] = _direction_table(model, kin)
    return kin


def _unit(model: ForceModel, i: int, theta: np.ndarray, col: Any) -> tuple[Any, Any]:
    """(cos θ, sin θ) of body i: from its first two joints for a link (no trigonometry), constants for a
    block on a ground guide, else from θ."""
    first, second, length = model.axes[i]
    if second is not None:
        return (col(f"{second}.x") - col(f"{first}.x")) / length, (col(f"{second}.y") - col(f"{first}.y")) / length
    if length is not None:  # a block on a ground guide never turns
        return math.cos(length), math.sin(length)
    return np.cos(theta), np.sin(theta)


def _direction_table(model: ForceModel, kin: dict[str, Any]) -> np.ndarray:
    """(n_directions, 2, n): world components of x, y and every slider's u and n over the samples."""
    n = kin["n"]
    out = np.empty((len(model.directions), 2, n))
    out[0, 0], out[0, 1], out[1, 0], out[1, 1] = 1.0, 0.0, 0.0, 1.0
    index = {b: i for i, b in enumerate(model.bodies)}
    for k, d in enumerate(model.directions[2:], start=2):
        const = _constant_direction(model.mechanism, d)
        if const is not None:
            out[k, 0], out[k, 1] = const
            continue
        th = kin["theta"][index[d[1]]]  # a block's θ is its axis direction
        ux, uy = np.cos(th), np.sin(th)
        out[k] = (ux, uy) if d[0] == "u" else (-uy, ux)
    return out


def _coefficients(model: ForceModel, kin: dict[str, Any]) -> np.ndarray:
    """(n_variable, n): the coefficients that change with the positions, every sample (the constant
    ones, ±1 and a ground slider's axis components, stay in the block plans).

    The moment of a world x/y force is a signed moment arm (−Δy, Δx); a slider's directions on a
    moving guide turn with it, and so do their moments.
    """
    e = model.entries
    n_var = int(e["var_row"].max(initial=-1)) + 1
    values = np.empty((n_var, kin["n"]))
    sel = e["arm"]
    values[e["var_row"][sel]] = e["arm_coef"][:, None] * kin["arms"][e["app"][sel], e["arm_comp"]]
    dirs = kin["directions"]
    sel = e["turning"]
    if len(sel):
        values[e["var_row"][sel]] = e["sign"][sel, None] * dirs[e["dir"][sel], e["kind"][sel]]
    sel = e["cross"]
    if len(sel):
        a, d = kin["arms"][e["app"][sel]], dirs[e["dir"][sel]]
        values[e["var_row"][sel]] = e["sign"][sel, None] * (a[:, 0] * d[:, 1] - a[:, 1] * d[:, 0])
    return values


def _full_values(model: ForceModel, variable: np.ndarray) -> np.ndarray:
    """(nnz, n): every structurally nonzero coefficient (constant ones broadcast)."""
    e = model.entries
    out = np.repeat(e["fixed"][:, None], variable.shape[1], axis=1)
    var = e["var_row"] >= 0
    out[var] = variable[e["var_row"][var]]
    return out


def _arm(kin: dict[str, Any], model: ForceModel, point: str, body: int) -> tuple[np.ndarray, np.ndarray]:
    """r_point − r_G of a body [m], over the samples."""
    px, py = kin["points"][point]
    return px - kin["gx"][body], py - kin["gy"][body]


def _right_hand_side(model: ForceModel, kin: dict[str, Any], t: np.ndarray) -> np.ndarray:
    """(n_eq, n): m·a_G − m·g − loads (x, y) and I·α − moments of the loads about G, per body."""
    mech = model.mechanism
    g = mech.gravity or (0.0, 0.0)
    m = model.mass[:, None]
    rhs = np.empty((model.n_eq, kin["n"]))
    rhs[0::3] = m * (kin["agx"] - g[0])
    rhs[1::3] = m * (kin["agy"] - g[1])
    rhs[2::3] = model.inertia[:, None] * kin["alpha"]
    index = {b: i for i, b in enumerate(model.bodies)}
    for ld in mech.loads:
        i = index[ld.body]
        v = load_values(ld, t)
        if ld.kind == "torque":
            rhs[3 * i + 2] -= v
            continue
        ax, ay = _arm(kin, model, ld.point, i)
        rhs[3 * i] -= v[:, 0]
        rhs[3 * i + 1] -= v[:, 1]
        rhs[3 * i + 2] -= ax * v[:, 1] - ay * v[:, 0]
    return rhs


def _solve_blocks(model: ForceModel, values: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Block forward substitution over the diagonal blocks, every sample at once: (n_unknowns, n)."""
    n = rhs.shape[1]
    x = np.zeros((len(model.unknowns), n))
    for plan in model.plans:
        b = rhs[plan["rows"]]
        if len(plan["const_cols"]):
            b = b - plan["c_const"] @ x[plan["const_cols"]]
        if len(plan["var_cols"]):
            b = b - plan["spread"] @ (values[plan["var_rows"]] * x[plan["var_cols"]])
        x[plan["cols"]] = _solve_block(plan, values, b)
    return x


def _solve_block(plan: dict[str, Any], values: np.ndarray, b: np.ndarray) -> np.ndarray:
    """One diagonal block for every sample: division, Cramer's rule, or batched LU above 2 × 2."""
    k, n = len(plan["cols"]), b.shape[1]
    if k <= 2:  # coefficients as scalars (constant) or rows (variable)
        a: list[list[Any]] = [[plan["a_const"][r, c] for c in range(k)] for r in range(k)]
        for r, c, v in plan["inner_var"]:
            a[r][c] = values[v]
        if k == 1:
            return b / a[0][0]
        det = a[0][0] * a[1][1] - a[0][1] * a[1][0]
        return np.array([a[1][1] * b[0] - a[0][1] * b[1], a[0][0] * b[1] - a[1][0] * b[0]]) / det
    full = np.repeat(plan["a_const"][:, :, None], n, axis=2)
    for r, c, v in plan["inner_var"]:
        full[r, c] = values[v]
    try:
        return np.linalg.solve(full.transpose(2, 0, 1), b.T[:, :, None])[:, :, 0].T
    except np.linalg.LinAlgError:
        return np.full((k, n), np.nan)


def _solve_least_squares(model: ForceModel, values: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
    """Minimum-norm solution of a redundant (or structurally deficient) system, and which unknowns it
    leaves free: those with a component in the null space of the equations at any sample."""
    e, n = model.entries, rhs.shape[1]
    a = np.zeros((n, model.n_eq, len(model.unknowns)))
    a[:, e["row"], e["col"]] = _full_values(model, values).T
    u, s, vh = np.linalg.svd(a, full_matrices=True)
    smax = s.max(axis=1, keepdims=True) if s.size else np.zeros((n, 1))
    keep = s > RANK_TOL * smax
    inv = np.where(keep, 1.0 / np.where(keep, s, 1.0), 0.0)
    k = s.shape[1]
    coef = np.einsum("nij,in->nj", u[:, :, :k], rhs) * inv
    x = np.einsum("nkj,nk->jn", vh[:, :k, :], coef)
    residual = np.einsum("nij,jn->in", a, x) - rhs
    scale = np.abs(rhs).max(initial=0.0) + np.abs(a).max(initial=0.0) * np.abs(x).max(initial=0.0)
    bad = np.abs(residual).max(axis=0) > 1e-9 * max(scale, 1e-300)
    if np.any(bad):
        j = int(np.argmax(bad))
        raise ForceError(
            f"{model.mechanism.name}: the forces cannot balance at sample {j}: the mechanism has more freedom "
            "than its drivers fix",
            sample=j,
        )
    rows = np.zeros((n, len(model.unknowns), len(model.unknowns)))
    rows[:, :k, :] = vh[:, :k, :] * keep[:, :, None]
    in_null = 1.0 - np.einsum("nij,nij->nj", rows, rows)  # diagonal of the null-space projector
    free = np.any(in_null > 1e-8, axis=0)
    rank = int(keep.sum(axis=1).min()) if n else 0
    message = ""
    if np.any(free):
        message = (
            f"{model.mechanism.name}: the force equations have rank {rank} for {len(model.unknowns)} unknowns "
            f"(redundant constraints): {np.count_nonzero(free)} reaction component(s) are statically indeterminate"
        )
    return x, free, message


def _columns(model: ForceModel, kin: dict[str, Any], x: np.ndarray, free: np.ndarray) -> dict[str, np.ndarray]:
    """Output columns: drivers, pin reactions (with magnitudes), sliders, shaking; none for free unknowns."""
    idx = {u: i for i, u in enumerate(model.unknowns)}
    cols: dict[str, np.ndarray] = {}
    for u, i in idx.items():
        if u.endswith((".torque", ".force")) and not free[i]:
            cols[u] = x[i]
    for j, c, b in reaction_names(model.mechanism):
        base = f"{j}:{c}>{b}"
        ix, iy = idx[f"{base}.fx"], idx[f"{base}.fy"]
        if not (free[ix] or free[iy]):
            cols[f"{base}.fx"], cols[f"{base}.fy"] = x[ix], x[iy]
            cols[f"{base}.mag"] = np.hypot(x[ix], x[iy])
    for s in model.mechanism.sliders:
        for what in ("normal", "moment"):
            i = idx[f"{s}.{what}"]
            if not free[i]:
                cols[f"{s}.{what}"] = x[i]
    cols.update(_shaking(model, kin, x))
    return cols


def _shaking(model: ForceModel, kin: dict[str, Any], x: np.ndarray) -> dict[str, np.ndarray]:
    """Σ of what the ground receives through its pins, guides and drivers; moment about the origin."""
    n = kin["n"]
    fx, fy, mz = np.zeros(n), np.zeros(n), np.zeros(n)
    dirs = kin["directions"]
    for e in model.effects:
        if e.body >= 0:
            continue
        if e.direction < 0:
            mz += e.sign * x[e.unknown]
            continue
        dx, dy = dirs[e.direction]
        px, py = kin["points"][e.point]
        gx, gy = e.sign * x[e.unknown] * dx, e.sign * x[e.unknown] * dy
        fx += gx
        fy += gy
        mz += px * gy - py * gx
    return {f"{SHAKING}.fx": fx, f"{SHAKING}.fy": fy, f"{SHAKING}.moment": mz}
