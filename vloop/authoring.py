"""Mechanisms written from dimensions: their t = 0 assembly, and the same mechanism with closed coordinates.

A file written from dimensions (:mod:`vloop.files.dimensions`) states every moving body's shape; the coordinates
of its moving joints are hints, rough or missing. Its t = 0 configuration is the problem the compiler solves at
t = 0, solved here with the compiler's own steps (:func:`vloop.compiler.loop_system`) and the solver's own
closed forms (:func:`vloop.core.solver.close_at_start`), group by group in solving order:

* a closed-form dyad (RRR, RRP, RPR) has two assemblies: the one named in ``[solver] branches`` ("open" /
  "crossed" for a four-joint loop; "keep" / "flip" relative to the hints), else the one nearer the hinted joints
  it places (the sum of squared distances); with neither, the file is ambiguous and refused, naming the key to
  add; where neither assembly exists, the dimensions cannot close and the file is refused;
* a block of coupled loops (Newton) needs hints: every assembly Newton finds from them and from 512 seeded starts
  is listed, and the one nearest the hints taken (root-sum-square distance over the hinted joints the block places);
  refused where none closes, or where the next nearest is less than 1.5 times as far (the hints do not tell the two
  apart). The report names it ("assembly 1 of n found") and both distances.

The result is the same Mechanism with its coordinates closed to round-off (the ground's as given), slider axes
at their t = 0 directions, points and centres of mass where their bodies carry them; the branches it was asked
for are in its coordinates now (``[solver] branches`` is left out). It loads and compiles as any file,
reproducing itself (``vloop assemble``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .compiler import compile_system, loop_system
from .core.solver import close_at_start
from .errors import MechanismError
from .method.assembly import DEFAULT_ASSEMBLY_TOL, STARTS, assemblies, inputs_at_start
from .method.branches import NAMES, branch_sigma, dyad_branch
from .method.loops import Block, LoopSystem, term_values
from .method.structure import Structure, block_structure
from .model import MassProperties, Mechanism, Slider, joint_mean, to_world

DYADS = ("RRR", "RRP", "RPR")
TIE = 1e-12  # two assemblies whose squared distances to the hints differ by less than this·size² are a tie


@dataclass
class Choice:
    """How one block's assembly was chosen: its loop (number from 1; ``others``: the further loops of a Newton block,
    (number, label) each), the branch (a dyad's name and side, or "σ = ±1"; a Newton block's "assembly k of n
    found") and why ("named", "nearest the hints", "the only assembly")."""

    loop: int
    label: str
    branch: str
    why: str
    others: tuple[tuple[int, str], ...] = ()

    def text(self) -> str:
        loops = [f"{self.loop} ({self.label})", *(f"{n} ({label})" for n, label in self.others)]
        return f"loop{'s' if self.others else ''} {' and '.join(loops)}: {self.branch} ({self.why})"


@dataclass
class Assembly:
    """What :func:`assemble_mechanism` did: the choices per dyad, how far each hinted joint moved [length], the
    closed mechanism's compiled LoopSystem."""

    choices: list[Choice] = field(default_factory=list)
    moved: dict[str, float] = field(default_factory=dict)
    system: LoopSystem | None = None

    def lines(self, units: str) -> list[str]:
        """The report as text, one line per dyad and one for the hints."""
        out = [c.text() for c in self.choices]
        if self.moved:
            worst = max(self.moved, key=self.moved.__getitem__)
            out.append(f"hinted joints moved by up to {self.moved[worst]:.4g} {units} ({worst})")
        return out


def assemble_mechanism(mech: Mechanism) -> tuple[Mechanism, Assembly]:
    """The t = 0 assembly of a mechanism written from dimensions (see the module docstring): the closed Mechanism and
    the report. Raises MechanismError where the dimensions cannot close or the choice is ambiguous."""
    from .files.options import instance

    instance(mech, "mech", Mechanism, "a Mechanism (vloop.load)")
    if not mech.from_dimensions:
        raise MechanismError(f"{mech.source}: not written from dimensions: its coordinates are its assembly")
    system, structure = loop_system(mech)
    report = Assembly()
    if structure.over_determined:  # redundant: no dyad by dyad; the compiler's least squares from the coordinates
        q = _redundant(system)
    else:
        q = _dyad_by_dyad(system, structure, report)
    closed = _closed_mechanism(mech, system, q, report)
    _check_inputs(mech, report)
    report.system = compile_system(closed)
    return closed, report


def _dyad_by_dyad(system: LoopSystem, structure: Structure, report: Assembly) -> np.ndarray:
    """The t = 0 variables, block by block in solving order (the choices made recorded in ``report``)."""
    mech = system.mechanism
    q = system.coords_q.copy()
    if mech.drivers:
        q[list(system.drivers)] = inputs_at_start(mech)
    blocks = list(block_structure(system, structure, q, "auto"))  # σ at the hints, replaced below
    _check_branches(system, blocks)
    for i, block in enumerate(blocks):
        if block.kind == "newton":
            report.choices.append(_newton(system, blocks, q, i))
        elif block.kind == "PP":
            q = _close(system, blocks, q, i)
        else:
            blocks[i], q, choice = _choose(system, blocks, q, i)
            report.choices.append(choice)
    return q


def _redundant(system: LoopSystem) -> np.ndarray:
    """A redundant linkage moves only because its dimensions agree exactly: its coordinates must be given and close
    (within assembly_tolerance); the compiler assembles it from them, by least squares on every loop."""
    mech = system.mechanism
    if mech.unplaced:
        raise MechanismError(
            f"{mech.source}: [joints] the linkage is redundant (more loop equations than unknowns), so it is assembled "
            f"from its coordinates: give those of {', '.join(mech.unplaced)}",
            entry="joints",
        )
    return compile_system(
        dataclasses.replace(mech, options={k: v for k, v in mech.options.items() if k != "branches"})
    ).q0


def _check_branches(system: LoopSystem, blocks: list[Block]) -> None:
    """Every loop [solver] branches names is a dyad with two assemblies."""
    mech = system.mechanism
    dyads = {b.loops[0] for b in blocks if b.kind in DYADS}
    for number in sorted(mech.options.get("branches", {})):
        if number - 1 not in dyads:
            what = (
                f"there is no loop {number}"
                if number > len(system.loops)
                else f"loop {number} ({system.loops[number - 1].label}) is not a dyad with two assembly branches"
            )
            raise MechanismError(f"{mech.source}: [solver] branches: {what}", entry="solver")


def _close(system: LoopSystem, blocks: list[Block], q: np.ndarray, i: int) -> np.ndarray:
    """Blocks 0..i closed from q by the solver's closed forms; MechanismError where block i cannot close."""
    out, why = close_at_start(system, tuple(blocks), q, i)
    if out is None:
        raise _cannot_close(system, blocks[i], why)
    return out


def _cannot_close(system: LoopSystem, block: Block, why: str) -> MechanismError:
    mech = system.mechanism
    loop = system.loops[block.loops[0]]
    inputs = ", ".join(
        f"{d.symbol} = {x:.6g} {'rad' if d.kind == 'crank' else mech.units}"
        for d, x in zip(mech.drivers, inputs_at_start(mech), strict=True)
    )
    because = "its links cannot reach" if why.startswith("the loop cannot close") else why
    return MechanismError(
        f"{mech.source}: [links] the dimensions cannot close loop {loop.index + 1} ({loop.label}) at t = 0 with "
        f"{inputs or 'no input'}: {because}; check the lengths and the input's t = 0 value",
        entry="links",
    )


TIE_RATIO = 1.5  # a Newton block's second-nearest assembly less than this many times as far as the nearest: refused


def _newton(system: LoopSystem, blocks: list[Block], q: np.ndarray, i: int) -> Choice:
    """A block of coupled loops: every assembly Newton finds from the hints and from many starts
    (:func:`vloop.method.assembly.assemblies`), the one nearest the hints taken (root-sum-square distance over the
    hinted joints the block places, those where the assemblies differ), written into ``q``; refused where none
    closes, or where the next nearest is less than :data:`TIE_RATIO` times as far (the hints do not tell them
    apart)."""
    block, mech = blocks[i], system.mechanism
    labels = ", ".join(f"{li + 1} ({system.loops[li].label})" for li in block.loops)
    unhinted = sorted({j for v in block.unknowns for j in _defining_joints(system, v) if j in mech.unplaced})
    if unhinted:
        raise MechanismError(
            f"{mech.source}: [joints] loops {labels} are solved together by Newton, which starts from the "
            f"coordinates: give rough coordinates of {', '.join(unhinted)}",
            entry="joints",
        )
    found = assemblies(system, list(block.loops), list(block.unknowns), q)
    if not found:
        raise MechanismError(
            f"{mech.source}: [joints] loops {labels} do not close: no assembly found from the coordinates or from "
            f"{STARTS} other starts; check the dimensions",
            entry="joints",
        )
    known = set(system.drivers) | {v for b in blocks[: i + 1] for v in b.unknowns}
    dist = _hint_distances(system, found, _placed(system, known, set(block.unknowns)))
    order = sorted(range(len(found)), key=dist.__getitem__)
    best = order[0]
    first, *rest = (system.loops[li] for li in block.loops)
    choice = Choice(first.index + 1, first.label, f"assembly 1 of {len(found)} found", "the only assembly found",
                    tuple((loop.index + 1, loop.label) for loop in rest))  # fmt: skip
    if len(found) > 1:
        near, next_ = dist[best], dist[order[1]]
        if next_ < TIE_RATIO * near:
            raise MechanismError(
                f"{mech.source}: [joints] loops {labels} have {len(found)} assemblies at t = 0 and the coordinates are "
                f"about as near two of them ({near:.3g} and {next_:.3g} {mech.units}: less than {TIE_RATIO:g} times "
                "as far): give closer coordinates of the joints they place",
                entry="joints",
            )
        choice.why = f"nearest the coordinates: {near:.3g} {mech.units} against {next_:.3g} for the next"
    q[:] = found[best]
    return choice


def _hint_distances(system: LoopSystem, found: list[np.ndarray], placed: list[int]) -> list[float]:
    """Root-sum-square distance of each assembly from the hints, over the hinted joints in ``placed`` whose position
    differs between the assemblies (a joint all of them put at one place tells nothing)."""
    mech = system.mechanism
    hinted = [k for k in placed if system.point_names[k] in mech.joints and system.point_names[k] not in mech.unplaced]
    pos = np.array([term_values(system, row) @ system.path[:, hinted] for row in found]).reshape(len(found), -1)
    moving = np.ptp(np.abs(pos - pos[0]), axis=0) > 1e-9 * mech.scale if len(found) > 1 else np.ones(len(hinted), bool)
    hints = np.array([complex(*mech.joints[system.point_names[k]]) for k in hinted])
    return [float(math.sqrt(np.sum(np.abs(p - hints)[moving] ** 2))) for p in pos]


def _defining_joints(system: LoopSystem, v: int) -> tuple[str, ...]:
    """The joints whose coordinates give variable v's starting value (a link's first two, a slider's joint)."""
    mech = system.mechanism
    if v < system.n_angles:
        return mech.links[system.angle_links[v]].joints[:2]
    return (mech.sliders[system.slider_names[v - system.n_angles]].joint,)


# ---------------------------------------------------------------- a dyad's two assemblies


def _choose(system: LoopSystem, blocks: list[Block], q: np.ndarray, i: int) -> tuple[Block, np.ndarray, Choice]:
    """Dyad i on the branch the file names, else the one nearer the hints: (its block, the variables, the choice)."""
    block, mech = blocks[i], system.mechanism
    loop = system.loops[block.loops[0]]
    cands: dict[float, np.ndarray] = {}
    why = ""
    for sigma in (1.0, -1.0):
        trial = [*blocks[:i], dataclasses.replace(block, sigma=sigma), *blocks[i + 1 :]]
        out, why_not = close_at_start(system, tuple(trial), q, i)
        if out is None:
            why = why or why_not
        else:
            cands[sigma] = out
    if not cands:
        raise _cannot_close(system, block, why)
    known = set(system.drivers) | {v for b in blocks[: i + 1] for v in b.unknowns}
    placed = _placed(system, known, set(block.unknowns))
    sides = {s: dyad_branch(system, dataclasses.replace(block, sigma=s), out, blocks) for s, out in cands.items()}
    names = {s: b.name if b else None for s, b in sides.items()}
    wanted = mech.options.get("branches", {}).get(loop.index + 1)
    if wanted in NAMES:
        branch_sigma(system, block, wanted, blocks)  # refused where the names do not apply to this dyad
    sigma, how = _pick(system, cands, names, placed, wanted, block)
    branch = sides[sigma].text() if sides[sigma] else f"assembly σ = {sigma:+.0f}"
    return dataclasses.replace(block, sigma=sigma), cands[sigma], Choice(loop.index + 1, loop.label, branch, how)


def _pick(
    system: LoopSystem,
    cands: dict[float, np.ndarray],
    names: dict[float, str | None],
    placed: list[int],
    wanted: str | None,
    block: Block,
) -> tuple[float, str]:
    """The branch σ and why: the name asked for, else the hints ("keep" the nearer, "flip" the other)."""
    mech, li = system.mechanism, block.loops[0]
    where = f"{mech.source}: [solver] branches: loop {li + 1} ({system.loops[li].label})"
    if wanted in NAMES:
        hit = [s for s, n in names.items() if n == wanted]
        if len(hit) != 1:  # none, or (at a toggle, the middle joint on the line) no side to tell
            raise MechanismError(f"{where} cannot be assembled {wanted} at t = 0", entry="solver")
        return hit[0], "named"
    if len(cands) == 1:
        if wanted == "flip":
            raise MechanismError(f"{where} has one assembly at t = 0: there is none to flip to", entry="solver")
        return next(iter(cands)), "the only assembly"
    near, how = _nearest(system, cands, names, placed, block)
    return (-near, "named: flip, the one farther from the hints") if wanted == "flip" else (near, how)


def _nearest(
    system: LoopSystem, cands: dict[float, np.ndarray], names: dict, placed: list[int], block: Block
) -> tuple[float, str]:
    """The assembly nearer the hints: the coordinates of the joints it places (sum of squared distances), else —
    where it places no hinted joint, as a block turning on its guide — the angles and slides the coordinates draw
    for its unknowns (angles times the size). Ambiguous (refused) where neither tells the two apart."""
    mech = system.mechanism
    tie = TIE * mech.scale**2
    hinted = [k for k in placed if system.point_names[k] in mech.joints and system.point_names[k] not in mech.unplaced]
    d = {s: _distance(system, out, hinted) for s, out in cands.items()}
    if hinted and abs(d[1.0] - d[-1.0]) > tie:
        near = min(d, key=d.__getitem__)
        return near, f"nearest the coordinates: {math.sqrt(d[near]):.3g} {mech.units} against {math.sqrt(d[-near]):.3g}"
    drawn = [v for v in block.unknowns if not set(_defining_joints(system, v)) & set(mech.unplaced)]
    d = {s: _drawn_distance(system, out, drawn) for s, out in cands.items()}
    if drawn and abs(d[1.0] - d[-1.0]) > tie:
        return min(d, key=d.__getitem__), "nearest the angles and slides the coordinates draw"
    why = "no joint it places has coordinates" if not hinted else "the coordinates are as near one as the other"
    raise _ambiguous(system, block, placed, names, why)


def _drawn_distance(system: LoopSystem, q: np.ndarray, variables: list[int]) -> float:
    """Σ of squared differences of ``variables`` from the values the coordinates draw (angles times the size)."""
    out = 0.0
    for v in variables:
        diff = float(q[v] - system.coords_q[v])
        out += (system.mechanism.scale * math.remainder(diff, 2 * math.pi)) ** 2 if v < system.n_angles else diff**2
    return out


def _ambiguous(system: LoopSystem, block: Block, placed: list[int], names: dict, why: str) -> MechanismError:
    mech, li = system.mechanism, block.loops[0]
    joints = [system.point_names[k] for k in placed if system.point_names[k] in mech.joints]
    ground = mech.links[mech.ground].joints
    joints += [j for v in block.unknowns for j in _defining_joints(system, v) if j not in joints and j not in ground]
    fix = f"give rough coordinates of {', '.join(joints) or 'its joints'} in [joints]"
    if all(n is not None for n in names.values()):
        fix += f', or [solver] branches = {{ {li + 1} = "open" }} (or "crossed")'
    return MechanismError(
        f"{mech.source}: [joints] loop {li + 1} ({system.loops[li].label}) has two assemblies at t = 0 and nothing "
        f"chooses between them ({why}): {fix}",
        entry="joints",
    )


def _point_vars(system: LoopSystem) -> list[set[int]]:
    """The variables each point's position depends on (the angles and sliders along its path)."""
    n_angles = system.n_angles
    out = []
    for k in range(len(system.point_names)):
        terms = np.flatnonzero(system.path[:, k])
        used = {int(system.t_ang[t]) for t in terms if system.t_ang[t] >= 0 and system.t_r[t] > 0}
        out.append(used | {n_angles + int(system.t_sl[t]) for t in terms if system.t_sl[t] >= 0})
    return out


def _placed(system: LoopSystem, known: set[int], now: set[int]) -> list[int]:
    """The points (indices into point_names) whose positions the known variables give, and which ``now`` moves."""
    return [k for k, used in enumerate(_point_vars(system)) if used <= known and used & now]


def _distance(system: LoopSystem, q: np.ndarray, points: list[int]) -> float:
    """Σ |position − coordinates|² over ``points`` (indices into point_names)."""
    mech = system.mechanism
    z = term_values(system, q) @ system.path[:, points]
    return float(
        sum(abs(p - complex(*mech.joints[system.point_names[k]])) ** 2 for p, k in zip(z, points, strict=True))
    )


# ---------------------------------------------------------------- the closed mechanism


def _closed_mechanism(mech: Mechanism, system: LoopSystem, q: np.ndarray, report: Assembly) -> Mechanism:
    """The mechanism at the assembly q: joints and points where the loops put them (the ground's as given), slider
    axes turned with their guides, centres of mass on their bodies, the branches asked for in the coordinates."""
    z = term_values(system, q) @ system.path
    pos = {n: (p.real, p.imag) for n, p in zip(system.point_names, z.tolist(), strict=True)}
    fixed = set(mech.links[mech.ground].joints)
    joints = {j: xy if j in fixed else pos[j] for j, xy in mech.joints.items()}
    report.moved = {j: math.dist(xy, joints[j]) for j, xy in mech.joints.items() if j not in fixed | set(mech.unplaced)}
    points = {n: p if p.link == mech.ground else dataclasses.replace(p, at=pos[n]) for n, p in mech.points.items()}
    sliders = {n: _axis_at(system, q, s) for n, s in mech.sliders.items()}
    options = {k: v for k, v in mech.options.items() if k != "branches"}  # the coordinates now hold them
    closed = dataclasses.replace(
        mech, joints=joints, points=points, sliders=sliders, options=options, masses={}, unplaced=(), reach=None
    )
    bodies = closed.bodies()
    masses = {}
    for n, mp in mech.masses.items():
        com = to_world(bodies[n], mp.local) if mp.local is not None else joint_mean(bodies[n], closed.body_joints(n))
        masses[n] = MassProperties(mp.mass, mp.inertia, com, mp.local)
    return dataclasses.replace(closed, masses=masses)


def _axis_at(system: LoopSystem, q: np.ndarray, sl: Slider) -> Slider:
    """A slider on a moving guide with its axis at the assembly: the guide's θ there plus the axis's angle in the
    guide's frame (stated, or as the coordinates draw it: 0 for a one-joint guide, whose θ is the axis)."""
    if sl.guide not in system.angle_links:
        return sl  # the ground's axis is a dimension
    a = system.angle_links.index(sl.guide)
    alpha = sl.angle if sl.angle is not None else math.atan2(sl.axis[1], sl.axis[0]) - system.coords_q[a]
    th = float(q[a]) + alpha
    return dataclasses.replace(sl, axis=(math.cos(th), math.sin(th)))


def _check_inputs(mech: Mechanism, report: Assembly) -> None:
    """A driver whose t = 0 value was taken from the coordinates needs coordinates within the assembly tolerance."""
    tol = mech.options.get("assembly_tolerance", DEFAULT_ASSEMBLY_TOL) * mech.scale
    worst = max(report.moved.values(), default=0.0)
    for d in mech.drivers:
        if d.from_coordinates and worst > tol:
            key = "theta0" if d.kind == "crank" else "s0"
            raise MechanismError(
                f"{mech.source}: [{d.entry}] give {key} (the input's value at t = 0): it was taken from the "
                f"coordinates, which are only hints here (the assembly moved a joint by {worst:.3g} {mech.units}, "
                f"more than assembly_tolerance = {tol / mech.scale:g} of the size)",
                entry=d.entry,
            )


# ---------------------------------------------------------------- the closed mechanism as the user's text


def closed_text(source: str, closed: Mechanism) -> str:
    """The file's own text (``source``) with the coordinates of ``closed`` (:func:`assemble_mechanism`'s): every
    moving joint's coordinates replaced where they are written (a joint without any added to ``[joints]``), ``[solver]
    branches`` taken out (the coordinates now hold the branches; a comment says so); every other line, comment
    and layout as written (tomlkit keeps them)."""
    import tomlkit

    doc = tomlkit.parse(source)
    joints = doc["joints"]
    ground = set(closed.links[closed.ground].joints)  # as given: the text stays as written
    for name, (x, y) in closed.joints.items():
        if name in ground:
            continue
        new = tomlkit.array([float(x), float(y)])
        if name in joints:
            old = joints[name]
            new.trivia.comment_ws, new.trivia.comment = old.trivia.comment_ws, old.trivia.comment
        joints[name] = new
    solver = doc.get("solver")
    if solver is not None and "branches" in solver:
        named = ", ".join(f'{k} = "{v}"' for k, v in solver["branches"].items())
        del solver["branches"]
        solver.add(tomlkit.comment(f"branches = {{ {named} }} was assembled by vloop assemble: now in the coordinates"))
    text = tomlkit.dumps(doc)
    return text if text.endswith("\n") else text + "\n"
