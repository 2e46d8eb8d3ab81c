"""A mechanism as a MuJoCo model (MJCF): bodies on hinge and slide joints, its loops closed by ``connect``.

The tree is the one the Pinocchio engine builds (:func:`validators.pinocchio.plan_tree`: every slider pair
kept, pins kept in file order, one pin cut per independent loop); each cut pin is an equality ``connect``
between a site on each of its two bodies. Each body's frame is vloop's body frame (:meth:`Mechanism.bodies`:
a link's first joint at its origin and its second on +x; a block's joint at its origin, x along the slider
axis), so at ``qpos = 0`` every body sits where the file's coordinates put it at t = 0.

Units: metres, kilograms, seconds when the file's length unit is known (``vloop.model.LENGTH_UNITS``; every
length is converted), else the file's own length unit. Masses and inertias are the file's ``[masses]``
(a body it omits gets :data:`MIN_MASS` of the heaviest, since MuJoCo moves no massless body); without
``[masses]``, the Exudyn engine's default (:func:`validators.exudyn_model.rod_frame_mass`: rods of 1 kg/m
along each link's outline, blocks of side 10 % of the size). Gravity is the file's (none without it).

The driver of a kinematic input is a servo on the input's coordinate — a fixed tendon equal to the driven
link's absolute angle θ − θ(0) (the sum of the hinges from the ground to it), or a slider's s − s(0):

* ``drive <target>``: an integrator actuator, its activation the set point (act' = ctrl), force
  kp·(act − length): the set point moves at the speed ``ctrl``;
* ``drive <target> rate``: a velocity actuator, force kv·(ctrl − rate): the input's rate fed forward;
* the driven joint carries an armature (a flywheel) of :data:`ARMATURE` times the mechanism's inertia, so
  the servo can be stiff (kp = armature·ω_n², ω_n = :data:`SERVO_OMEGA` / timestep, critically damped);
  the armature adds armature·ẍ to the driver's torque, and changes nothing of the motion.

A constant-speed input needs nothing more: the keyframe ``t0`` (written by :mod:`validators.models`) holds
the assembled positions, consistent rates, the set point and ctrl = the input's speed. A varying input, or
a load that follows a table, asks the user's controller for ctrl each step (the engine,
:mod:`validators.mujoco`, sets the set point and its rate from the driver every step).

Loads: a torque load is a motor on the tendon of its body's absolute angle (its virtual work τ·δφ), a force
load a motor on a site with a world-fixed reference frame (``refsite``), each with ctrl = 1 and the load as
its gear, in N and N·m (a table's value is the ctrl times a gear of 1).

Geometry (no contacts: ``contype = conaffinity = 0``): each link as capsules along its outline, each block
as a box, each ground pivot as a cylinder, each ground guide as a thin box along its axis; sites at every
joint and tracer point (named ``BODY/POINT``), read by the engine for positions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from xml.sax.saxutils import quoteattr

import numpy as np

from vloop.mechanism import Body, Mechanism

from ..exudyn_model import BLOCK_SIZE, _hull, rod_frame_mass
from ..pinocchio import TreePlan, plan_tree

ROD = 0.02  # capsule radius of a link's drawing, fraction of the mechanism's size
MIN_MASS = 1e-6  # a body without mass in the file: this fraction of the heaviest body's mass (MuJoCo needs > 0)
ARMATURE = 1e4  # the driven joint's armature: this many times the mechanism's inertia scale Σ (m·size² + I)
SERVO_OMEGA = 0.2  # the servo's natural frequency times the timestep (explicit in kp: stable below ~1)
# Equality constraints: MuJoCo's soft constraints leave (1 − d)·a·τ² of violation for an acceleration demand a
# (impedance d, time constant τ): with d = 0.9999 and τ = 2 steps (MuJoCo's least), ~4e-12·a at a 1e-4 s step.
SOLREF = "{tc:.6g} 1"
SOLIMP = "0.9999 0.9999 0.001 0.5 2"
STEPS_PER_RAD = 1000  # the timestep moves no input more than 1 mrad (a crank) or 1e-3 of the size (a slider)


@dataclass
class Layout:
    """What the engine needs to read the model back: names in the MJCF and how the inputs map to them."""

    scale: float  # metres per file length unit (1 for an unknown unit: the file's own)
    plan: TreePlan
    joint_of: dict[str, str]  # body -> the MJCF joint that carries it from its parent
    sign: dict[str, float]  # slide joints: +1 where qpos = s − s(0), −1 where the guide hangs below its block
    tendons: list[dict[str, float]] = field(default_factory=list)  # per driver: joint -> coefficient
    offsets: list[float] = field(default_factory=list)  # per driver: its input at qpos = 0 (θ0 or s0, file units)
    timestep: float = 1e-4
    omega: float = 0.0  # the servos' natural frequency [rad/s]
    armature: dict[str, float] = field(default_factory=dict)  # driven joint -> its flywheel [kg·m², kg]
    cuts: list[str] = field(default_factory=list)


def _q(angle: float) -> str:
    return f"{math.cos(angle / 2):.17g} 0 0 {math.sin(angle / 2):.17g}"


def _v(*xs: float) -> str:
    return " ".join(f"{x:.17g}" for x in xs)


def _rot(th: float) -> np.ndarray:
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def length_scale(mech: Mechanism) -> float:
    """Metres per file length unit, 1 where the unit is not one vloop converts."""
    from vloop.model import LENGTH_UNITS

    return LENGTH_UNITS.get(mech.units.strip().lower(), 1.0)


def masses(mech: Mechanism, k: float) -> dict[str, tuple[float, np.ndarray, float]]:
    """Body -> (mass [kg], centre of mass in the body frame [m], inertia about it [kg·m²]); k: metres per unit."""
    bodies = mech.bodies()
    out: dict[str, tuple[float, np.ndarray, float]] = {}
    if mech.masses:
        for name, mp in mech.masses.items():
            b = bodies[name]
            com = mp.local if mp.local is not None else _rot(b.theta0).T @ (np.asarray(mp.com) - b.origin)
            out[name] = (float(mp.mass), np.asarray(com, float) * k, float(mp.inertia))
        heaviest = max((m for m, _, _ in out.values()), default=1.0) or 1.0
        least = MIN_MASS * heaviest
        for name in mech.moving_links:  # MuJoCo moves no body without mass, nor one without inertia (a point)
            m, com, inertia = out.get(name, (0.0, np.zeros(2), 0.0))
            out[name] = (max(m, least), com, max(inertia, least * (mech.scale * k) ** 2))
        return out
    size = mech.scale * k
    for name in mech.moving_links:
        b = bodies[name]
        if b.kind == "block":
            m = BLOCK_SIZE * size
            out[name] = (m, np.zeros(2), m * (BLOCK_SIZE * size) ** 2 / 6.0)
        else:
            pts = np.array(list(b.local.values()), float) * k
            out[name] = rod_frame_mass(pts, size)
    return out


def _outline(b: Body, k: float) -> np.ndarray:
    """A body's drawn outline: its members' convex hull (a bar: its two ends), in metres."""
    pts = np.array(list(b.local.values()), float) * k
    return _hull(pts) if len(pts) > 2 else pts


def _geoms(b: Body, k: float, size: float) -> list[str]:
    r = ROD * size
    if b.kind == "block":
        h = 0.5 * BLOCK_SIZE * size
        return [f'<geom type="box" size="{_v(h, 0.5 * h, 0.5 * h)}" rgba="0.9 0.62 0 1"/>']
    hull = _outline(b, k)
    if len(hull) < 2:
        return [f'<geom type="sphere" size="{r:.6g}" rgba="0 0.45 0.7 1"/>']
    pairs = [(hull[0], hull[1])] if len(hull) == 2 else [(hull[i], hull[(i + 1) % len(hull)]) for i in range(len(hull))]
    return [
        f'<geom type="capsule" fromto="{_v(a[0], a[1], 0, c[0], c[1], 0)}" size="{r:.6g}" rgba="0 0.45 0.7 1"/>'
        for a, c in pairs
    ]


def _ground(mech: Mechanism, bodies: dict[str, Body], k: float, size: float) -> list[str]:
    """The ground's pivots as cylinders, its guides as rails, sites at its joints."""
    out = []
    g = bodies[mech.ground]
    for j, xy in g.local.items():
        x, y = np.asarray(xy) * k
        if len(mech.bodies_at(j)) > 1:
            out.append(
                f'<geom type="cylinder" pos="{_v(x, y, -ROD * size)}" size="{1.5 * ROD * size:.6g} '
                f'{ROD * size:.6g}" rgba="0.4 0.4 0.4 1"/>'
            )
        out.append(f'<site name={quoteattr(f"{mech.ground}/{j}")} pos="{_v(x, y, 0)}"/>')
    for sl in mech.sliders.values():
        if sl.guide == mech.ground:
            x, y = np.asarray(mech.joints[sl.joint]) * k
            a = math.atan2(sl.axis[1], sl.axis[0])
            out.append(
                f'<geom type="box" pos="{_v(x, y, -ROD * size)}" quat="{_q(a)}" '
                f'size="{_v(2.5 * BLOCK_SIZE * size, 0.25 * ROD * size, 0.25 * ROD * size)}" rgba="0.4 0.4 0.4 1"/>'
            )
    return out


def _joint(
    mech: Mechanism, bodies: dict[str, Body], parent: str, child: str, edge, k: float
) -> tuple[str, str, str, float]:
    """(the child's pos and quat in its parent's frame, its joint element, the slide sign) for one tree edge."""
    P, C = bodies[parent], bodies[child]
    turn = C.theta0 - P.theta0
    name = f"{child}@{edge.joint}"
    if edge.kind == "pin":
        pos = np.asarray(P.local[edge.joint]) - _rot(turn) @ np.asarray(C.local[edge.joint])
        at = np.asarray(C.local[edge.joint]) * k
        xml = f'<joint name={quoteattr(name)} type="hinge" axis="0 0 1" pos="{_v(at[0], at[1], 0)}"/>'
        return _v(*pos * k, 0), xml, name, 1.0
    if child == edge.b:  # a block below its guide: along its own x axis (the slider's)
        pos = _rot(P.theta0).T @ (np.asarray(mech.joints[edge.joint]) - np.asarray(P.origin))
        return _v(*pos * k, 0), f'<joint name={quoteattr(name)} type="slide" axis="1 0 0"/>', name, 1.0
    # a guide below its block: it slides the other way along the block's axis
    pos = _rot(P.theta0).T @ (np.asarray(C.origin) - np.asarray(P.origin))
    axis = _rot(-turn) @ np.array([1.0, 0.0])
    return _v(*pos * k, 0), f'<joint name={quoteattr(name)} type="slide" axis="{_v(axis[0], axis[1], 0)}"/>', name, -1.0


def _path(layout: Layout, mech: Mechanism, body: str) -> dict[str, float]:
    """The hinges from the ground to ``body``: their sum is the body's θ − θ(0)."""
    out: dict[str, float] = {}
    b = body
    while b in layout.plan.parent:
        p, e = layout.plan.parent[b]
        if e.kind == "pin":
            out[layout.joint_of[b]] = 1.0
        b = p
    return out


def _slider_s0(mech: Mechanism, bodies: dict[str, Body], name: str) -> float:
    """A slider's s at the file's coordinates: (P − O_guide)·u (O: the guide's frame origin, the world's for
    the ground)."""
    sl = mech.sliders[name]
    g = bodies[sl.guide]
    return float((np.asarray(mech.joints[sl.joint]) - np.asarray(g.origin)) @ np.asarray(sl.axis))


def timestep(mech: Mechanism) -> float:
    """The step [s]: the fastest input moves 1/STEPS_PER_RAD rad (or that fraction of the size) per step, at
    most 1/20 of the shortest sample interval and 1e-3 s."""
    from vloop.drivers import evaluate_all

    t = np.asarray(mech.times, float)
    _, xd, _ = evaluate_all(mech, t)
    scale = np.array([1.0 if d.kind == "crank" else mech.scale for d in mech.drivers])
    rate = float(np.max(np.abs(xd) / scale)) if xd.size else 0.0
    h = 1e-3 if rate == 0 else min(1e-3, 1.0 / (STEPS_PER_RAD * rate))
    dt = np.diff(t)
    if dt.size:
        h = min(h, float(np.min(dt[dt > 0])) / 20 if np.any(dt > 0) else h)
    return h


def build(mech: Mechanism) -> tuple[str, Layout]:
    """The MJCF text of ``mech`` (no keyframe) and its :class:`Layout`."""
    k = length_scale(mech)
    pivots = {d.pivot for d in mech.drivers if d.kind == "crank"}
    plan = plan_tree(mech, cut_preference=[j for j in mech.joints if j not in pivots])  # inputs next to the ground
    joint_of = {c: f"{c}@{plan.parent[c][1].joint}" for c in plan.order[1:]}
    layout = Layout(k, plan, joint_of, {}, timestep=timestep(mech))
    mass = masses(mech, k)
    world = _world(mech, layout, mass)
    tendons, actuators = _drives(mech, layout, mass)
    actuators += _loads(mech, layout, mech.bodies(), k, tendons)
    equality = [
        f"    <connect name={quoteattr(f'cut {j}: {a}-{b}')} site1={quoteattr(f'{a}/{j}')} "
        f"site2={quoteattr(f'{b}/{j}')} "
        f'solref="{SOLREF.format(tc=2 * layout.timestep)}" solimp="{SOLIMP}"/>'
        for j, a, b in plan.cuts
    ]
    layout.cuts = [f"cut {j}: {a}-{b}" for j, a, b in plan.cuts]
    g = (0.0, 0.0) if mech.gravity is None else mech.gravity  # m/s²: the model is in metres where gravity is given
    units = "m, kg, s" if k != 1.0 or mech.units.strip().lower() == "m" else f"{mech.units}, kg, s"
    text = "\n".join(
        [
            f"<mujoco model={quoteattr(mech.name)}>",
            f"  <!-- {_comment(mech.title or mech.name)}: written by vloop export at t = 0; "
            f"units {_comment(units)} -->",
            '  <compiler angle="radian" autolimits="true"/>',
            f'  <option timestep="{layout.timestep:.17g}" gravity="{_v(g[0], g[1], 0)}" integrator="RK4" '
            'solver="Newton" tolerance="1e-14" iterations="100" jacobian="dense" cone="pyramidal"/>',
            f'  <default><geom contype="0" conaffinity="0"/><site size="{0.5 * ROD * mech.scale * k:.6g}" '
            'rgba="0.2 0.2 0.2 1"/></default>',
            *("  <worldbody>", *world, "  </worldbody>"),
            *("  <tendon>", *tendons, "  </tendon>"),
            *("  <equality>", *equality, "  </equality>"),
            *("  <actuator>", *actuators, "  </actuator>"),
            "</mujoco>",
        ]
    )
    return _with_armature(text, layout.armature), layout


def _world(mech: Mechanism, layout: Layout, mass: dict[str, tuple[float, np.ndarray, float]]) -> list[str]:
    """The worldbody's lines: the ground's geometry and sites, then the tree of bodies, each inside its parent."""
    k, plan, bodies = layout.scale, layout.plan, mech.bodies()
    size = mech.scale * k
    children: dict[str, list[str]] = {}
    for c in plan.order[1:]:
        children.setdefault(plan.parent[c][0], []).append(c)

    def body_xml(name: str, depth: int) -> list[str]:
        p, e = plan.parent[name]
        pos, joint, _, layout.sign[name] = _joint(mech, bodies, p, name, e, k)
        m, com, inertia = mass[name]
        pad = "  " * depth
        lines = [
            f'{pad}<body name={quoteattr(name)} pos="{pos}" quat="{_q(bodies[name].theta0 - bodies[p].theta0)}">',
            f"{pad}  {joint}",
            f'{pad}  <inertial pos="{_v(com[0], com[1], 0)}" mass="{m:.17g}" '
            f'diaginertia="{_v(inertia, inertia, inertia)}"/>',
        ]
        lines += [f"{pad}  {g}" for g in _geoms(bodies[name], k, size)]
        lines += [
            f'{pad}  <site name={quoteattr(f"{name}/{j}")} pos="{_v(*np.asarray(xy) * k, 0)}"/>'
            for j, xy in bodies[name].local.items()
        ]
        for c in children.get(name, []):
            lines += body_xml(c, depth + 1)
        return [*lines, f"{pad}</body>"]

    world = [f"    {g}" for g in _ground(mech, bodies, k, size)]
    for c in children.get(plan.root, []):
        world += body_xml(c, 2)
    return world


def _drives(
    mech: Mechanism, layout: Layout, mass: dict[str, tuple[float, np.ndarray, float]]
) -> tuple[list[str], list[str]]:
    """Each input's tendon and its two actuators (the set point's servo, the rate's feed-forward); the driven
    joints' armatures, offsets and tendons into ``layout``."""
    bodies, size = mech.bodies(), mech.scale * layout.scale
    rotary = sum(m * size**2 + i for m, _, i in mass.values())  # the mechanism's inertia scale [kg·m²]
    omega = layout.omega = SERVO_OMEGA / layout.timestep
    tendons, actuators = [], []
    for i, d in enumerate(mech.drivers):
        if d.kind == "crank":
            coef = _path(layout, mech, d.target)
            layout.offsets.append(bodies[d.target].theta0)
            inertia = ARMATURE * rotary
        else:
            coef = dict([_slide_of(layout, mech, d.target)])
            layout.offsets.append(_slider_s0(mech, bodies, d.target))
            inertia = ARMATURE * rotary / size**2  # per metre of travel
        layout.tendons.append(coef)
        layout.armature[next(iter(coef))] = inertia  # the driven body's own joint carries the flywheel
        tname = f"input {i} {d.symbol}"
        tendons.append(f"    <fixed name={quoteattr(tname)}>" + _tendon(coef) + "</fixed>")
        kp, kv = inertia * omega**2, 2.0 * inertia * omega  # critically damped
        actuators.append(
            f'    <general name={quoteattr(f"drive {d.target}")} tendon={quoteattr(tname)} dyntype="integrator" '
            f'gainprm="{kp:.17g}" biastype="affine" biasprm="0 {-kp:.17g} 0"/>'
        )
        actuators.append(
            f'    <velocity name={quoteattr(f"drive {d.target} rate")} tendon={quoteattr(tname)} kv="{kv:.17g}"/>'
        )
    return tendons, actuators


def _slide_of(layout: Layout, mech: Mechanism, slider: str) -> tuple[str, float]:
    """The slide joint between a slider's block and its guide, and its sign (qpos = sign·(s − s(0)) [m])."""
    for child, (_, e) in layout.plan.parent.items():
        if e.kind == "slider" and e.b == slider:
            return layout.joint_of[child], layout.sign[child]
    raise ValueError(f"{mech.name}: slider {slider} is not in the tree")  # plan_tree keeps every slider pair


def _with_armature(text: str, armature: dict[str, float]) -> str:
    for j, a in armature.items():
        text = text.replace(f"<joint name={quoteattr(j)} ", f'<joint name={quoteattr(j)} armature="{a:.17g}" ', 1)
    return text


def _tendon(coef: dict[str, float]) -> str:
    return "".join(f'<joint joint={quoteattr(j)} coef="{c:.17g}"/>' for j, c in coef.items())


def _loads(mech: Mechanism, layout: Layout, bodies: dict[str, Body], k: float, tendons: list[str]) -> list[str]:
    """A motor per load: a torque on its body's angle tendon, a force at a site against a world-fixed frame."""
    out = []
    for i, ld in enumerate(mech.loads):
        name = f"load {i} on {ld.body}"
        if ld.kind == "torque":
            tname = f"angle of {ld.body} ({i})"
            coef = _path(layout, mech, ld.body)
            tendons.append(f"    <fixed name={quoteattr(tname)}>" + _tendon(coef) + "</fixed>")
            gear = float(ld.value) if ld.profile is None else 1.0
            out.append(f'    <motor name={quoteattr(name)} tendon={quoteattr(tname)} gear="{gear:.17g}"/>')
        else:
            site = f"{ld.body}/{ld.point}"
            ref = f"{mech.ground}/{next(iter(bodies[mech.ground].local))}"  # a world site: its axes are the world's
            gears = [ld.value] if ld.profile is None else [(1.0, 0.0), (0.0, 1.0)]
            out += [
                f"    <general name={quoteattr(name + ('' if len(gears) == 1 else ' ' + 'xy'[n]))} "
                f"site={quoteattr(site)} "
                f'refsite={quoteattr(ref)} gear="{_v(fx, fy, 0, 0, 0, 0)}"/>'
                for n, (fx, fy) in enumerate(gears)
            ]
    return out


def _comment(text: str) -> str:
    """Text safe inside an XML comment (no "--", no control characters)."""
    clean = "".join(c for c in text if c.isprintable())
    return clean.replace("--", "- -")
