"""Mechanisms written from dimensions: their t = 0 assembly, and the same mechanism with closed coordinates.

A file written from dimensions (:mod:`vloop.files.dimensions`) states every moving body's shape; the coordinates
of its moving joints are hints, rough or missing. Its t = 0 configuration is the problem the compiler solves at
t = 0, solved here with the compiler's own steps (:func:`vloop.compiler.loop_system`) and the solver's own
closed forms (:func:`vloop.core.solver.close_at_start`), group by group in solving order:

* a closed-form dyad (RRR, RRP, RPR) has two assemblies: the one named in ``[solver] branches`` ("open" /
  "crossed" for a four-joint loop; "keep" / "flip" relative to the hints), else the one nearer the hinted joints
  it places (the sum of squared distances); with neither, the file is ambiguous and refused, naming the key to
  add; where neither assembly exists, the dimensions cannot close and the file is refused;
* a block of coupled loops (Newton) starts from the hints (they must be given) and must converge.

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
from .method.assembly import DEFAULT_ASSEMBLY_TOL, close_group, inputs_at_start
from .method.loops import Block, Loop, LoopSystem, branch_name, term_values
from .method.structure import Structure, block_structure
from .model import MassProperties, Mechanism, Slider, joint_mean, to_world

DYADS = ("RRR", "RRP", "RPR")
TIE = 1e-12  # two assemblies whose squared distances to the hints differ by less than this·size² are a tie


@dataclass
class Choice:
    """How one dyad's assembly was chosen: its loop (number from 1), the branch name ("open"/"crossed", or "σ = ±1"
    where the loop has no four joints) and why ("named", "nearest the hints", "the only assembly")."""

    loop: int
    label: str
    branch: str
    why: str


@dataclass
class Assembly:
    """What :func:`assemble_mechanism` did: the choices per dyad, how far each hinted joint moved [length], the
    closed mechanism's compiled LoopSystem."""

    choices: list[Choice] = field(default_factory=list)
    moved: dict[str, float] = field(default_factory=dict)
    system: LoopSystem | None = None

    def lines(self, units: str) -> list[str]:
        """The report as text, one line per dyad and one for the hints."""
        out = [f"loop {c.loop} ({c.label}): {c.branch} ({c.why})" for c in self.choices]
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
            _newton(system, block, q)
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
    lp = system.loops[block.loops[0]]
    inputs = ", ".join(
        f"{d.symbol} = {x:.6g} {'rad' if d.kind == 'crank' else mech.units}"
        for d, x in zip(mech.drivers, inputs_at_start(mech), strict=True)
    )
    because = "its links cannot reach" if why.startswith("the loop cannot close") else why
    return MechanismError(
        f"{mech.source}: [links] the dimensions cannot close loop {lp.index + 1} ({lp.label}) at t = 0 with "
        f"{inputs or 'no input'}: {because}; check the lengths and the input's t = 0 value",
        entry="links",
    )


def _newton(system: LoopSystem, block: Block, q: np.ndarray) -> None:
    """A block of coupled loops, closed by the assembly's Newton from the hints (which it needs)."""
    mech = system.mechanism
    labels = ", ".join(f"{li + 1} ({system.loops[li].label})" for li in block.loops)
    unhinted = sorted({j for v in block.unknowns for j in _defining_joints(system, v) if j in mech.unplaced})
    if unhinted:
        raise MechanismError(
            f"{mech.source}: [joints] loops {labels} are solved together by Newton, which starts from the "
            f"coordinates: give rough coordinates of {', '.join(unhinted)}",
            entry="joints",
        )
    if not close_group(system, list(block.loops), list(block.unknowns), q):
        raise MechanismError(
            f"{mech.source}: [joints] loops {labels} do not close from the coordinates given: the dimensions "
            "cannot close there, or the coordinates are too far from an assembly (give closer ones)",
            entry="joints",
        )


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
    names = {s: _branch(system, out, loop, known) for s, out in cands.items()}
    wanted = mech.options.get("branches", {}).get(loop.index + 1)
    sigma, how = _pick(system, cands, names, placed, wanted, block)
    branch = names[sigma] or f"assembly σ = {sigma:+.0f}"
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
    if wanted in ("open", "crossed"):
        if all(n is None for n in names.values()):
            raise MechanismError(
                f"{where} is not a four-joint loop: 'open'/'crossed' name a four-bar's branches; give rough "
                "coordinates of its joints instead",
                entry="solver",
            )
        hit = [s for s, n in names.items() if n == wanted]
        if not hit:
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
    na = system.n_angles
    out = []
    for k in range(len(system.point_names)):
        terms = np.flatnonzero(system.path[:, k])
        used = {int(system.t_ang[t]) for t in terms if system.t_ang[t] >= 0 and system.t_r[t] > 0}
        out.append(used | {na + int(system.t_sl[t]) for t in terms if system.t_sl[t] >= 0})
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


def _branch(system: LoopSystem, q: np.ndarray, loop: Loop, known: set[int]) -> str | None:
    """ "open" or "crossed" for a four-joint loop whose joints the known variables place, else None."""
    needs = _point_vars(system)
    on_loop = {j for _, j in loop.nodes} & set(system.point_names)
    if any(not needs[system.point_names.index(j)] <= known for j in on_loop):
        return None
    return branch_name(system, q, loop)


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
        mech, joints=joints, points=points, sliders=sliders, options=options, masses={}, unplaced=()
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
