"""Branch names of a closed-form RRR dyad: "open" and "crossed", as the textbooks use them (Norton, ch. 4).

A dyad P–M–Q (two links meeting at the middle joint M) closes between two known points, its ends P and Q. Its
two assemblies are the two signs of the square root in its closed form, i.e. the two sides of the line P→Q that
M can lie on; that side stays the same along a motion until a toggle (M on the line: the links in line, the
discriminant zero), so it names a branch, whatever the quadrilateral looks like at one instant.

The line's direction is taken as the textbook takes it for a four-bar O2–A–B–O4 driven at O2: from the dyad's
end on the input side (A) to its end on the frame side (O4). The frame side is the end whose other link is known
first (the ground before a driven link, a driven link before a solved one, an earlier block before a later one);
where both ends' other links are known at the same step, the line has no direction and the dyad no name.

The map, made once here: **open = M to the left of P→Q, crossed = M to the right** (counter-clockwise positive
angles). For the textbook layout (O4 on the +x axis from O2, θ2 in the first quadrant) "open" is the convex
quadrilateral; a mirror image swaps the two names, as it does in the textbook's frame. The names apply to a
four-joint loop (a four-bar, or a four-bar inside a larger linkage); every other RRR dyad is described by its
side alone ("E right of P→O6"). Where M lies on the line (within :data:`ON_LINE` of the two lengths), no side
is named: :func:`branch_name` refuses rather than pick.

Public: :func:`dyad_branch` (the side at a configuration, with the joints' names), :func:`branch_name`
("open" / "crossed" / None) and :func:`branch_sigma` (the block's assembly sign σ that puts a dyad on a named
branch). ``vloop info``, the file's ``[solver] branches``, ``vloop assemble`` and the studio all use these.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import MechanismError
from .loops import ORIGIN, Block, LoopSystem, term_values, turning_with

__all__ = ["CROSSED", "NAMES", "ON_LINE", "OPEN", "DyadBranch", "branch_name", "branch_sigma", "dyad_branch"]

OPEN, CROSSED = "open", "crossed"
NAMES = (OPEN, CROSSED)
ON_LINE = 1e-9  # |sin| of the angle P→Q, P→M at or below this: M is on the line (positions hold ~1e-12 of the size)


@dataclass(frozen=True)
class DyadBranch:
    """The side of a dyad's middle joint: ``start`` → ``end`` is the line P→Q (input side → frame side),
    ``middle`` the joint M, ``side`` +1 (left), −1 (right) or 0 (on the line: no name), ``name`` "open" /
    "crossed" for a four-joint loop (None elsewhere or on the line), ``sigma`` the block's assembly sign."""

    loop: int  # index from 0
    start: str
    middle: str
    end: str
    side: float
    name: str | None
    sigma: float
    four_joints: bool

    def text(self) -> str:
        """E.g. "open (B left of A→O4)", "E right of P→O6", "B on the line A→O4"."""
        where = "on the line" if self.side == 0 else ("left of" if self.side > 0 else "right of")
        what = f"{self.middle} {where} {self.start}→{self.end}"
        return f"{self.name} ({what})" if self.name else what


@dataclass(frozen=True)
class _Ends:
    start: str
    middle: str
    end: str
    orient: float  # +1 where ``start`` is the end of the block's first unknown link (σ's own reference), else −1
    four_joints: bool


def _ends(system: LoopSystem, block: Block, blocks: Sequence[Block] | None = None) -> _Ends | None:
    """The dyad's joints P, M, Q in the textbook's order, or None (not an RRR dyad, its two links not meeting at a
    joint of the loop, or neither end's other link known before the other's)."""
    if block.kind != "RRR" or len(block.loops) != 1:
        return None
    loop = system.loops[block.loops[0]]
    first, second = (system.angle_links[v] for v in block.unknowns)
    on = {}  # body → its joints at the loop's corners
    for body, joint in loop.corners:
        if joint != ORIGIN:
            on.setdefault(body, []).append(joint)
    shared = set(on.get(first, ())) & set(on.get(second, ()))
    if len(shared) != 1 or len(on[first]) != 2 or len(on[second]) != 2:
        return None
    (middle,) = shared
    p1 = next(j for j in on[first] if j != middle)  # the first link's far end: σ's reference
    p2 = next(j for j in on[second] if j != middle)
    order = system.blocks if blocks is None else blocks
    known = [_known_at(system, order, _neighbour(loop.corners, j, link)) for j, link in ((p1, first), (p2, second))]
    if known[0] == known[1]:
        return None
    start, end, orient = (p1, p2, 1.0) if known[0] > known[1] else (p2, p1, -1.0)
    return _Ends(start, middle, end, orient, len(loop.label.split("–")) == 4)


def _neighbour(corners: tuple, joint: str, link: str) -> str | None:
    """The other body the loop crosses at ``joint`` (besides ``link``)."""
    return next((b for b, j in corners if j == joint and b != link), None)


def _known_at(system: LoopSystem, blocks: Sequence[Block], body: str | None) -> int:
    """When a body's pose is known: −2 the ground, −1 a driven variable, else the index of the block that solves
    it (an angle, or a translating block's slide)."""
    mech = system.mechanism
    if body is None or body == mech.ground:
        return -2
    n_angles = system.n_angles
    if body in system.angle_links:
        v = system.angle_links.index(body)
    elif body in system.slider_names:
        v = n_angles + system.slider_names.index(body)
    else:
        return -2
    if v in system.drivers:
        return -1
    return next((i for i, b in enumerate(blocks) if v in b.unknowns), len(blocks))


def _sides(system: LoopSystem, block: Block, q: np.ndarray) -> float:
    """The side (+1 left, −1 right, 0 on the line) of M from the first unknown link's far end to the other end, at
    ``q``: the sign of Im(conj(u1 + u2)·u1), u1, u2 the loop's vectors turning with the two links (traversed
    either way, the same sign), as the closed form's σ."""
    loop = system.loops[block.loops[0]]
    z = term_values(system, np.asarray(q, float))
    u1, u2 = (turning_with(system, loop, z, a) for a in block.unknowns)
    c = (np.conj(u1 + u2) * u1).imag
    if not abs(c) > ON_LINE * abs(u1 + u2) * abs(u1):
        return 0.0
    return math.copysign(1.0, c)


def dyad_branch(
    system: LoopSystem, block: Block, q: np.ndarray, blocks: Sequence[Block] | None = None
) -> DyadBranch | None:
    """The branch of an RRR dyad at the configuration ``q`` (variables; the joints of its loop must be placed by
    ``q``), or None where the dyad has no textbook line (see the module docstring). ``blocks``: the solving order
    (default: the system's)."""
    ends = _ends(system, block, blocks)
    if ends is None:
        return None
    s = _sides(system, block, q)
    side = s * ends.orient
    name = (OPEN if side > 0 else CROSSED) if ends.four_joints and side != 0 else None
    return DyadBranch(
        block.loops[0], ends.start, ends.middle, ends.end, side, name, s if s else block.sigma, ends.four_joints
    )


def branch_name(system: LoopSystem, block: Block, q: np.ndarray, blocks: Sequence[Block] | None = None) -> str | None:
    """ "open" or "crossed" for the RRR dyad of a four-joint loop at ``q``, None where the names do not apply;
    MechanismError where its middle joint lies on the line between its ends (no branch can be named there)."""
    b = dyad_branch(system, block, q, blocks)
    if b is None or not b.four_joints:
        return None
    if b.name is None:  # on the line
        loop = system.loops[block.loops[0]]
        raise MechanismError(
            f"{system.mechanism.source}: loop {loop.index + 1} ({loop.label}): {b.text()} (a toggle): neither "
            "open nor crossed",
            entry="solver",
        )
    return b.name


def branch_sigma(system: LoopSystem, block: Block, name: str, blocks: Sequence[Block] | None = None) -> float:
    """The assembly sign σ of ``block`` that puts its dyad on the branch ``name`` ("open" or "crossed"); a
    MechanismError naming the loop where the names do not apply to it."""
    loop = system.loops[block.loops[0]]
    where = f"{system.mechanism.source}: [solver] branches: loop {loop.index + 1} ({loop.label})"
    ends = _ends(system, block, blocks)
    if name not in NAMES:
        raise MechanismError(f"{where}: '{name}' is not a branch name (open, crossed)", entry="solver")
    if ends is None or not ends.four_joints:
        why = "is not a four-joint loop's RRR dyad"
        if block.kind == "RRR" and len(loop.label.split("–")) == 4:
            why = "has no input side (neither end of its dyad is known before the other)"
        raise MechanismError(
            f"{where} {why}; 'open'/'crossed' name a four-bar's branches — use 'flip' or 'keep', or hint the joints",
            entry="solver",
        )
    return ends.orient * (1.0 if name == OPEN else -1.0)
