"""Drawing geometry from a solved run: body poses and the vector loops head to tail.

Everything here is a pure function of a compiled :class:`~vloop.method.loops.LoopSystem` (its public
attributes only) and a :class:`~vloop.result.Result`, vectorized over samples:

* :func:`body_poses` — the pose (x, y, θ) of every body's frame per sample, the frame of
  :meth:`vloop.mechanism.Mechanism.bodies` (a link's first joint, x axis towards its second;
  a block's joint, x along the slider axis; the ground's frame is the world's).
* :func:`loop_chains` — each vector loop as the paper draws it: the chain of its vectors
  head to tail, z = (r + s)·e^{j(θ + δ)}, starting where the loop starts (a joint, or the
  world origin that ground sliders measure from), with the loop equation as ``vloop loops``
  prints it. The chain closes because the loop equation holds; its vertices fall on the
  joints the loop passes through.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..method.equations import Vector, equation_text, legend_text, vector_loops
from ..model import Mechanism
from ..result import Result

BLOCK_SIZE = (0.08, 0.045)  # slider block length and height in drawings, fractions of the mechanism size



@dataclass(frozen=True)
class LoopChain:
    """One vector loop drawn head to tail over a run.

    ``vertices`` [length, complex x + jy], shape (samples, len(vectors) + 1): the loop's start,
    then the head of each vector in turn; the last equals the first when the loop closes.
    ``joints``: (vertex index, joint name) for every joint the loop passes through, in order.
    ``start``: the joint the chain starts at; where it starts at the world origin (ground sliders
    measure from there), the ground joint placed at the origin, or None if there is none.
    """

    index: int
    label: str
    equation: str
    vectors: tuple[Vector, ...]
    start: str | None
    joints: tuple[tuple[int, str], ...]
    vertices: np.ndarray

    @property
    def number(self) -> int:
        """The loop's number as ``vloop loops`` prints it (1-based)."""
        return self.index + 1


def body_poses(mech: Mechanism, result: Result) -> dict[str, np.ndarray]:
    """Per body, an array (samples, 3) of its frame's x, y [length] and θ [rad, CCW from +x]."""
    n = len(result)
    poses = {mech.ground: np.zeros((n, 3))}
    for name, body in mech.bodies().items():
        if body.kind == "ground":
            continue
        origin = body.joints[0]
        poses[name] = np.column_stack([result[f"{origin}.x"], result[f"{origin}.y"], result[f"{name}.theta"]])
    return poses


def loop_chains(system: Any, result: Result) -> list[LoopChain]:
    """Every loop of ``system`` as a chain of vectors head to tail at each sample of ``result``.

    Vectors are z = (r + s)·e^{j(θ + δ)} with θ and s read from the Result's ``LINK.theta`` and
    ``SLIDER.s`` columns [length, rad]; a chain starts at its first joint's position in the Result
    (or at the world origin).
    """
    mech = system.mechanism
    equations = {eq.number - 1: eq for eq in vector_loops(system)[0]}
    theta = {name: result[f"{name}.theta"] for name in system.angle_links}
    s = {name: result[f"{name}.s"] for name in system.slider_names}
    chains = []
    for lp in system.loops:
        eq = equations[lp.index]
        equation = f"{equation_text(eq)} = 0"
        vectors = eq.vectors
        start = lp.nodes[0][1]
        start_name = start if start in mech.tracked_points else _origin_joint(system)
        z = np.zeros((len(result), len(vectors) + 1), complex)
        if start in mech.tracked_points:
            z[:, 0] = result[f"{start}.x"] + 1j * result[f"{start}.y"]
        for k, v in enumerate(vectors):
            mag = v.r + (s[v.slider] if v.slider is not None else 0.0)
            ang = (theta[v.link] if v.link is not None else 0.0) + v.delta
            z[:, k + 1] = mag * np.exp(1j * ang)
        joints = _joints_on_chain(system, lp, vectors)
        chains.append(LoopChain(lp.index, lp.label, equation, vectors, start_name, joints, np.cumsum(z, axis=1)))
    return chains


def _joints_on_chain(system: Any, lp: Any, vectors: tuple[Vector, ...]) -> tuple[tuple[int, str], ...]:
    """Which chain vertex each joint of the loop is, found once on the t = 0 assembly ``system.q0``.

    The loop's corners are visited in order; each joint is the first vertex at or after the previous
    joint's that lies on it (a pin between two bodies adds no vector, so both nodes share a vertex).
    """
    mech = system.mechanism
    q0 = np.asarray(system.q0, float)
    na = len(system.angle_links)
    phi = np.append(q0[:na], 0.0)
    s0 = np.append(q0[na:], 0.0)
    z0 = (system.t_r + s0[system.t_sl]) * np.exp(1j * (phi[system.t_ang] + system.t_delta))
    where = dict(zip(system.point_names, z0 @ system.path, strict=True))

    def at(joint: str) -> complex:
        return complex(where[joint]) if joint in where else 0j  # else: the world origin

    start = at(lp.nodes[0][1])
    vert = start + np.concatenate([[0j], np.cumsum([_value(v, q0, system) for v in vectors])])
    tol = 1e-9 * mech.scale
    origin = _origin_joint(system)
    out: list[tuple[int, str]] = []
    k = 0
    for _, joint in lp.corners:
        hits = np.flatnonzero(np.abs(vert[k:] - at(joint)) <= tol)
        if not len(hits):
            raise AssertionError(f"loop {lp.index + 1} ({lp.label}): no vertex of its chain lies on {joint}")
        k += int(hits[0])
        name = joint if joint in where else origin
        if name is not None and (not out or out[-1][1] != name):
            out.append((k, name))
    return tuple(out)


def _origin_joint(system: Any) -> str | None:
    """The ground joint placed at the world origin (it names the origin in loop labels), if any."""
    mech = system.mechanism
    for j in mech.links[mech.ground].joints:
        if math.hypot(*mech.joints[j]) <= 1e-12 * mech.scale:
            return j
    return None


def _value(v: Vector, q: np.ndarray, system: Any) -> complex:
    na = len(system.angle_links)
    th = q[system.angle_links.index(v.link)] if v.link is not None else 0.0
    s = q[na + system.slider_names.index(v.slider)] if v.slider is not None else 0.0
    return (v.r + s) * complex(math.cos(th + v.delta), math.sin(th + v.delta))


def equation_legend(system: Any) -> list[str]:
    """The lines after ``where`` in ``vloop loops``: what each letter stands for."""
    return [legend_text(item) for item in vector_loops(system)[1]]
