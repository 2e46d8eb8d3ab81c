"""Compile a Mechanism into its immutable LoopSystem: a short pipeline of named steps.

    graph → loops → unknowns → assembly at t = 0 → block structure → branches asked for in the file

(:func:`loop_system` is the first steps alone: :mod:`vloop.authoring` assembles a mechanism written from
dimensions from there.)

Each step is a function of its own module (:mod:`vloop.method.graph`, :mod:`vloop.method.assembly`,
:mod:`vloop.method.structure`); this module only strings them together. The last step re-assembles
t = 0 with the solver's closed forms when the file asks for another assembly branch.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .core.solver import assemble_blocks
from .errors import MechanismError
from .files.schema import SIZES
from .method.assembly import assemble, moved
from .method.branches import NAMES, branch_sigma
from .method.graph import MechanismGraph, build_graph, build_loops, cycle_basis, point_paths
from .method.loops import Block, LoopSystem
from .method.structure import Structure, analyse, block_structure
from .model import Body, Mechanism


def compile_system(mech: Mechanism, method: str | None = None) -> LoopSystem:
    """Graph → loops → unknowns → assembly at t = 0 → block structure → branches. Raises MechanismError.

    ``method``: "auto" (closed-form dyads where the structure allows, Newton elsewhere) or
    "newton" (one Newton block for the whole system); default from the file's [solver] table, else "auto".
    """
    method = method or mech.options.get("method", "auto")
    if mech.unplaced:
        raise MechanismError(
            f"{mech.source}: [joints] {', '.join(mech.unplaced[:5])} {'has' if len(mech.unplaced) == 1 else 'have'} no "
            "coordinates: a mechanism written from dimensions is assembled first (vloop.load does it; "
            "vloop.authoring.assemble_mechanism)",
            entry="joints",
        )
    system, structure = loop_system(mech)
    q0, report, z0 = assemble(system, structure)
    blocks = block_structure(system, structure, q0, method, z0)
    if mech.options.get("branches"):
        blocks, q0, report = _choose_branches(system, blocks, q0, report)
    return dataclasses.replace(system, blocks=blocks, q0=q0, assembly=report, method=method, cache={})


def loop_system(mech: Mechanism) -> tuple[LoopSystem, Structure]:
    """Graph → loops → unknowns → block-triangular structure: the LoopSystem before its t = 0 assembly (no blocks;
    its ``q0`` the coordinates' variables) and the groups its equations are solved in."""
    _check_size(mech)
    bodies = mech.bodies()
    mg = build_graph(mech, bodies)
    loops, C = build_loops(mg, mech, cycle_basis(mg.adj, mg.forest))
    system = _unknowns(mech, mg, loops, C, bodies)
    return system, analyse(system)


def _check_size(mech: Mechanism) -> None:
    """Refuse a mechanism too large or too small for the closed forms: a dyad's discriminant is a product of
    squared lengths (size⁴), which overflows beyond ~1e77 and loses its digits below ~1e-77 (measured: the
    textbook four-bar solves identically scaled from 1e-68 to 1e72 and fails to assemble at 1e78)."""
    lo, hi = SIZES
    size = max(mech.scale, mech.largest_dimension)
    if len(mech.joints) > 1 and not lo <= size <= hi:
        raise MechanismError(
            f"{mech.source}: [joints] the mechanism spans {size:.3g} {mech.units}: only sizes from {lo:g} to "
            f"{hi:g} of the units can be solved in double precision (lengths are squared twice); state the "
            f"coordinates in {'larger' if size > hi else 'smaller'} units",
            entry="joints",
        )


def _unknowns(mech: Mechanism, mg: MechanismGraph, loops: tuple, C: np.ndarray, bodies: dict[str, Body]) -> LoopSystem:
    """The variables (rotating links' angles, then slider displacements), the driven ones, the unknowns,
    and a LoopSystem without blocks, assembled at the typed coordinates."""
    ang, sl, r, delta = mg.terms.arrays()
    n_angles = len(mg.angle_links)
    driven = tuple(
        mg.angle_links.index(d.target) if d.kind == "crank" else n_angles + mg.slider_names.index(d.target)
        for d in mech.drivers
    )
    coords_q = np.array([bodies[n].theta0 for n in mg.angle_links] + mg.coords_s, float)
    unknowns = tuple(v for v in range(n_angles + len(mg.slider_names)) if v not in driven)
    link_outputs = tuple((name, *mg.owner[name]) for name in mech.moving_links)
    return LoopSystem(
        mech, mg.angle_links, mg.slider_names, ang, sl, r, delta, tuple(mg.terms.label), loops, C,
        mech.tracked_points, point_paths(mg.adj, mech, len(r), mg.forest), link_outputs, driven, unknowns, (), coords_q,
        coords_q, mg.parts, chords=tuple(mg.terms.parts.items()),
    )  # fmt: skip


def _choose_branches(
    system: LoopSystem, blocks: tuple[Block, ...], q0: np.ndarray, report: dict
) -> tuple[tuple[Block, ...], np.ndarray, dict]:
    """Put the dyads the file names in [solver] branches on the requested branch, then re-assemble t = 0."""
    mech = system.mechanism
    wanted: dict[int, str] = mech.options["branches"]
    by_loop = {b.loops[0]: i for i, b in enumerate(blocks) if len(b.loops) == 1}
    new = list(blocks)
    for number, choice in sorted(wanted.items()):
        li = number - 1
        if li >= len(system.loops):
            raise MechanismError(f"{mech.source}: [solver] branches: there is no loop {number}", entry="solver")
        i = by_loop.get(li)
        if i is None or blocks[i].kind not in ("RRR", "RRP", "RPR"):
            raise MechanismError(
                f"{mech.source}: [solver] branches: loop {number} ({system.loops[li].label}) is not a dyad with two "
                "assembly branches",
                entry="solver",
            )
        if choice in NAMES:
            new[i] = dataclasses.replace(blocks[i], sigma=branch_sigma(system, blocks[i], choice, blocks))
        elif choice == "flip":
            new[i] = dataclasses.replace(blocks[i], sigma=-blocks[i].sigma)
    if new == list(blocks):
        return blocks, q0, report
    q1 = assemble_blocks(system, tuple(new), q0)
    return tuple(new), q1, {**report, **moved(system, q1), "branches_flipped": True}
