"""What every force validator shares: the file's mass properties and loads read from the Mechanism,
the output naming convention, and the shaking force from the reported reactions.

Nothing here solves anything: the engines (:mod:`validators.pinocchio_forces`,
:mod:`validators.exudyn_forces`, :mod:`validators.analytic.forces`) compute the reactions each
their own way and only *report* them through :func:`force_result`, in vloop's column names
(docs/forces.md):

* ``LINK.torque`` / ``SLIDER.force`` — a driver's torque (ground on link, CCW) / force (guide on
  block along the axis u);
* ``JOINT:FROM>ON.fx|fy|mag`` — the force body FROM exerts on body ON at a pin; FROM is the pin's
  carrier: the ground if the ground is at the pin, else the first body naming the joint;
* ``SLIDER.normal`` (along n = k × u) and ``SLIDER.moment`` (about the slider joint) — the guide on
  the block;
* ``shaking.fx|fy|moment`` — what the moving parts exert on the ground (moment about the origin).

Units: SI (N, N·m); the file's lengths are converted with its ``units``.
"""

from __future__ import annotations

import math

import numpy as np

from vloop.forces import ForceResult, reaction_names  # the output's naming convention (public)
from vloop.mechanism import Load, Mechanism, length_factor


def factor(mech: Mechanism) -> float:
    """Metres per file length unit."""
    return length_factor(mech.units)


def mass_table(mech: Mechanism) -> dict[str, tuple[float, np.ndarray, float]]:
    """body → (mass [kg], centre of mass in the body frame [file units], inertia about it [kg·m²])."""
    frames = mech.bodies()
    out = {}
    for name, mp in mech.masses.items():
        b = frames[name]
        c, s = math.cos(b.theta0), math.sin(b.theta0)
        dx, dy = mp.com[0] - b.origin[0], mp.com[1] - b.origin[1]
        out[name] = (mp.mass, np.array([c * dx + s * dy, -s * dx + c * dy]), mp.inertia)
    return out


def load_series(load: Load, t: np.ndarray) -> np.ndarray:
    """A load at times ``t``: (n, 2) force [N] or (n,) torque [N·m]; tables are linear between rows."""
    t = np.asarray(t, float)
    if load.profile is None:
        shape = (len(t), 2) if load.kind == "force" else (len(t),)
        return np.broadcast_to(np.asarray(load.value, float), shape).copy()
    p = load.profile
    cols = [np.interp(t, p.t, p.values[:, i]) for i in range(p.values.shape[1])]
    return np.column_stack(cols) if load.kind == "force" else cols[0]


def force_result(
    mech: Mechanism,
    engine: str,
    t: np.ndarray,
    drivers: dict[str, np.ndarray],
    pins: dict[tuple[str, str], np.ndarray],
    sliders: dict[str, tuple[np.ndarray, np.ndarray]],
    positions: dict[str, np.ndarray],
    axes: dict[str, np.ndarray],
) -> ForceResult:
    """Columns from an engine's reactions [SI].

    ``drivers``: column name (``l2.torque`` / ``l4.force``) → values; ``pins``: (joint, body) → (n, 2)
    net pin force on that body; ``sliders``: name → (normal, moment); ``positions``: joint → (n, 2)
    world positions [m]; ``axes``: slider → (n, 2) unit axis u over the samples.
    """
    cols: dict[str, np.ndarray] = dict(drivers)
    for j, c, b in reaction_names(mech):
        f = pins[(j, b)]
        cols[f"{j}:{c}>{b}.fx"], cols[f"{j}:{c}>{b}.fy"] = f[:, 0], f[:, 1]
        cols[f"{j}:{c}>{b}.mag"] = np.hypot(f[:, 0], f[:, 1])
    for s, (normal, moment) in sliders.items():
        cols[f"{s}.normal"], cols[f"{s}.moment"] = normal, moment
    cols.update(shaking(mech, t, cols, positions, axes))
    return ForceResult(mech.name, engine, np.asarray(t, float), cols)


def shaking(
    mech: Mechanism,
    t: np.ndarray,
    cols: dict[str, np.ndarray],
    positions: dict[str, np.ndarray],
    axes: dict[str, np.ndarray],
) -> dict[str, np.ndarray]:
    """What the moving parts exert on the ground: minus everything the ground exerts on them
    (pin reactions, guide normal forces and moments, driver torques and forces); moment about the origin."""
    n = len(t)
    fx, fy, mz = np.zeros(n), np.zeros(n), np.zeros(n)

    def on_ground(f: np.ndarray, p: np.ndarray) -> None:
        nonlocal fx, fy, mz
        fx, fy = fx - f[:, 0], fy - f[:, 1]
        mz = mz - (p[:, 0] * f[:, 1] - p[:, 1] * f[:, 0])

    for j, c, b in reaction_names(mech):
        if c == mech.ground:
            on_ground(np.column_stack([cols[f"{j}:{c}>{b}.fx"], cols[f"{j}:{c}>{b}.fy"]]), positions[j])
    for s in mech.sliders.values():
        if s.guide != mech.ground:
            continue
        u = axes[s.name]
        nrm = np.column_stack([-u[:, 1], u[:, 0]])
        f = cols[f"{s.name}.normal"][:, None] * nrm
        if f"{s.name}.force" in cols:
            f = f + cols[f"{s.name}.force"][:, None] * u
        on_ground(f, positions[s.joint])
        mz = mz - cols[f"{s.name}.moment"]
    for d in mech.drivers:
        if d.kind == "crank":
            mz = mz - cols[f"{d.target}.torque"]
    return {"shaking.fx": fx, "shaking.fy": fy, "shaking.moment": mz}
