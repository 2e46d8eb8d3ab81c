"""Defects and quality of a synthesized linkage, found by re-solving it with vloop over its whole motion.

The classic failures of synthesis (Erdman & Sandor; Norton, ch. 5). A method that means its linkage to be in
a given configuration at each precision position (function and motion generation) names the defect from those
configurations (:mod:`.circuits`: the input's arcs and the dyad's assembly sign):

* **circuit defect** — the positions lie on different circuits: the linkage must be taken apart to pass
  through them;
* **branch defect** — on one circuit, but on different branches: a toggle lies between them;
* **order defect** — on one branch, but the positions are reached in another order than asked as the input
  moves one way.

The candidate's own file is then run by vloop from its first precision position with the input moving that
way, and the run confirms it: a run that stops at a limit before the last position is a branch defect (the
only name a search's candidate, whose positions are read off its own run, can have besides order);
* **no full rotation** — a full-turning input was required and the input cannot turn through 360°;
* **transmission angle** — the smallest transmission angle over the working motion is below the limit asked;
* **error** — an optimization's candidate misses a precision position by more than the tolerance asked.

A candidate with any of these is reported with its defects named, never ranked as a solution.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import compile, solve
from ..errors import MotionError
from ..method.loops import LoopSystem
from ..model import Mechanism
from ..result import Result
from .candidates import Candidate, Task
from .circuits import Verdict
from .linkages import Topology, lengths, reanchored

CIRCUIT_TOL = 1e-6  # of the task's scale: an exact method's error beyond this is not round-off
WORK_SAMPLES = 181  # samples of the working motion (plus every precision instant)
TURN_SAMPLES = 361  # samples of the full-turn check (1° apart)
TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Requirements:
    """What a solution must also do: turn its input fully; keep the transmission angle at or above
    ``min_transmission`` [rad] over its working motion; (an optimization's candidate) pass every precision
    position within ``tolerance`` of the task's size; keep its ground pivots inside ``pivots`` = (xmin, ymin,
    xmax, ymax) and every moving link's length (each side of a plate) within ``links`` = (min, max), lengths in
    the task's units."""

    full_rotation: bool = False
    min_transmission: float = 0.0
    tolerance: float | None = None
    pivots: tuple[float, float, float, float] | None = None
    links: tuple[float, float] | None = None

    def outside(self, mech: Mechanism) -> list[str]:
        """What of a mechanism lies outside the bounds asked (empty when nothing does or none were asked)."""
        out = []
        if self.pivots is not None:
            x0, y0, x1, y1 = self.pivots
            ground = [j for lk in mech.links.values() if lk.ground for j in lk.joints]
            for j in ground:
                x, y = mech.joints[j]
                if not (x0 <= x <= x1 and y0 <= y <= y1):
                    out.append(f"ground pivot {j} at ({x:.6g}, {y:.6g}) is outside pivots {list(self.pivots)}")
        if self.links is not None:
            lo, hi = self.links
            ground = {n for n, lk in mech.links.items() if lk.ground}
            for key, length in lengths(mech).items():
                if key.split(".")[0] not in ground and not lo <= length <= hi:
                    out.append(f"{key} = {length:.6g} is outside links [{lo:g}, {hi:g}]")
        return out


@dataclass
class Draft:
    """A linkage as a method proposes it: its mechanism (t = 0 at the start of the working motion), the
    instants ``times`` [s] at which it should reach the precision positions (in the order asked), the length
    ``span`` [s] of its working motion, the optimizer's own error and notes."""

    name: str
    method: str
    topology: Topology
    mechanism: Mechanism
    times: np.ndarray
    span: float
    search_error: float | None = None
    notes: tuple[str, ...] = ()
    extra: dict = field(default_factory=dict)
    verdict: Verdict | None = None  # the defect the method's configurations make (None: read it off the run)


def assess(draft: Draft, task: Task, req: Requirements) -> Candidate:
    """Re-solve a draft with vloop over its working motion and every precision instant; name its defects."""
    top = draft.topology
    times = np.asarray(draft.times, float)
    work = np.union1d(np.linspace(0.0, draft.span, WORK_SAMPLES), times[np.isfinite(times) & (times >= 0)])
    mech = reanchored(draft.mechanism, top, 0.0, work)
    system = compile(mech)
    res, stop = _solve(system, work)
    errors, angle_errors = _errors(res, times, task, top)
    defects, notes = _named(draft, times, errors, stop)
    off = np.nan_to_num(np.abs(errors), nan=0.0) > CIRCUIT_TOL * task.size
    if task.exact and not defects and np.any(off):
        # the configurations say the run meets every position: a run that misses one is named, never ranked
        defects.append("error")
        notes.append(f"the run misses position(s) {[k + 1 for k in np.nonzero(off)[0]]} its method meant to meet")
    grashof = grashof_class(system)
    full = _turns_fully(system, draft.span, stop)
    if req.full_rotation and not full:
        defects.append("no full rotation")
        notes.append(f"the input {top.input} cannot turn through a full revolution")
    outside = req.outside(mech)
    if outside:
        defects.append("bounds")
        notes.append("bounds: " + "; ".join(outside))
    mu = min_transmission(mech, res, system)
    if req.min_transmission > 0 and not mu >= req.min_transmission:
        defects.append("transmission angle")
        notes.append(
            f"minimum transmission angle {math.degrees(mu):.1f}° < {math.degrees(req.min_transmission):.1f}° asked"
        )
    worst = np.nanmax(np.abs(errors)) / task.size if np.any(np.isfinite(errors)) else math.nan
    if req.tolerance is not None and not task.exact and worst > req.tolerance:
        defects.append("error")
        notes.append(f"misses a precision position by {worst:.3g} of {task.scale} (tolerance {req.tolerance:g})")
    return Candidate(
        draft.name, draft.method, top.name, mech, top.input, top.guided, top.tracer, times,
        _inputs(res, times, top), errors, task.size, tuple(defects), tuple(notes), angle_errors,
        grashof, full, mu, None, draft.search_error, lengths(mech), dict(draft.extra),
    )  # fmt: skip


def _named(draft: Draft, times: np.ndarray, errors: np.ndarray, stop: str | None) -> tuple[list[str], list[str]]:
    """The defect the draft's configurations make (or, without them, the run's), and the notes that say why."""
    defects, notes = [], list(draft.notes)
    missed = [k + 1 for k in range(len(times)) if not np.isfinite(errors[k])]
    reached = f" (precision position{'s' if len(missed) > 1 else ''} {missed} not reached)" if missed else ""
    v = draft.verdict
    if v is not None and v.kind:
        defects.append(v.kind)
        notes.append(v.note + (f"; the run: {stop}" if stop else ""))
    elif stop is not None:
        defects.append("branch")
        notes.append(f"branch defect: {stop}{reached}")
    if v is None and len(times) > 1 and not np.all(np.diff(times) > 0) and "order" not in defects:
        defects.append("order")
        notes.append("order defect: the positions are not reached in the order asked as the input moves one way")
    return defects, notes


def _solve(system: LoopSystem, times: np.ndarray) -> tuple[Result, str | None]:
    """The run over ``times``, or the samples before it stopped and why."""
    try:
        return solve(system, times), None
    except MotionError as exc:
        part = exc.partial if exc.partial is not None else Result(system.mechanism.name, "vloop", np.zeros(0), {})
        return part, str(exc)


def _at(res: Result, t: np.ndarray) -> np.ndarray:
    """The sample index of each instant in ``t`` (−1 where the run has no such sample)."""
    k = np.searchsorted(res.t, t)
    k = np.clip(k, 0, max(len(res.t) - 1, 0))
    hit = (len(res.t) > 0) & np.isclose(res.t[k] if len(res.t) else t, t, rtol=0, atol=1e-12 * (1 + np.abs(t)))
    return np.where(hit, k, -1)


def _errors(res: Result, times: np.ndarray, task: Task, top: Topology) -> tuple[np.ndarray, np.ndarray | None]:
    """Error at each precision position: distance of the tracer [length] (and the guided body's angle error
    [rad] for poses), or the output's error (function generation); NaN where the motion did not get there."""
    k = _at(res, times)
    reached = k >= 0
    kk = np.where(reached, k, 0)
    if task.outputs is not None:
        out = res[task.output][kk] if len(res.t) else np.zeros(len(times))
        diff = out - task.outputs
        if task.output.endswith(".theta"):
            diff = np.angle(np.exp(1j * diff))
        return np.where(reached, np.abs(diff), np.nan), None
    z = res[f"{top.tracer}.x"][kk] + 1j * res[f"{top.tracer}.y"][kk] if len(res.t) else np.zeros(len(times))
    err = np.where(reached, np.abs(z - task.points), np.nan)
    if task.angles is None:
        return err, None
    th = res[f"{top.guided}.theta"][kk] if len(res.t) else np.zeros(len(times))
    # the body's angle in the file differs from the pose's reference by a constant: the first pose fixes it
    offset = th[0] - task.angles[0]
    dth = np.angle(np.exp(1j * (th - offset - task.angles)))
    return err, np.where(reached, np.abs(dth), np.nan)


def _inputs(res: Result, times: np.ndarray, top: Topology) -> np.ndarray:
    """The input angle [rad] at each precision instant (NaN where not reached)."""
    k = _at(res, times)
    if not len(res.t):
        return np.full(len(times), np.nan)
    th = res[f"{top.input}.theta"][np.where(k >= 0, k, 0)]
    return np.where(k >= 0, th, np.nan)


def _turns_fully(system: LoopSystem, span: float, stop: str | None) -> bool:
    """Whether the input turns through a full revolution from t = 0 (solved over one turn unless the working
    motion already covers one)."""
    omega = abs(system.mechanism.drivers[0].v0)
    turn = TWO_PI / omega
    if stop is None and span >= turn * (1 - 1e-12):
        return True
    try:
        solve(system, np.linspace(0.0, turn, TURN_SAMPLES))
    except MotionError:
        return False
    return True


def min_transmission(mech: Mechanism, res: Result, system: LoopSystem | None = None) -> float:
    """The smallest folded transmission angle [rad] of any dyad over the run (NaN without dyads or samples)."""
    from .. import transmission_angles

    if not len(res.t):
        return math.nan
    angles = transmission_angles(mech, res, system)
    return float(min((np.min(a.folded) for a in angles), default=math.nan))


def grashof_class(system: LoopSystem) -> str:
    """The Grashof class of the linkage's first four-bar loop ("" when it has none), as vloop names it."""
    from ..method.equations import grashof

    found = grashof(system)
    return found[0][1] if found else ""


_DYADS: dict[str, tuple] = {}


def population_transmission(topology: Topology, points: dict[str, np.ndarray], times: np.ndarray) -> np.ndarray:
    """The smallest folded transmission angle [rad] over the samples of each row of a population (rows, samples)
    arrays of joint positions (complex); NaN where a row has no motion. The dyads are the topology's (one
    structure for every member), the angle as :mod:`vloop.teaching.transmission` measures it."""
    from ..teaching.transmission import dyads, raw_angle

    if topology.name not in _DYADS:
        nominal = topology.mechanism(topology.nominal, name="nominal", omega=1.0, times=np.array([0.0]))
        _DYADS[topology.name] = (nominal, dyads(compile(nominal))[0])
    nominal, found = _DYADS[topology.name]
    cols = {f"{p}.{f}": getattr(z, part) for p, z in points.items() for f, part in (("x", "real"), ("y", "imag"))}
    view = Result("", "synthesis", np.asarray(times, float), cols)
    out = np.full(len(next(iter(points.values()))), np.inf)
    for d in found:
        raw = raw_angle(nominal, view, d)
        out = np.minimum(out, np.min(np.minimum(raw, np.pi - raw), axis=1))
    return np.where(np.isfinite(out), out, np.nan)
