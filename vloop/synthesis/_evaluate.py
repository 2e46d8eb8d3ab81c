"""The one door from synthesis to vloop's batched solver: many linkages of one topology, solved together.

A population is a table of linkages of one :class:`~vloop.synthesis.linkages.Topology`: each row the t = 0
coordinates of its joints and tracer (x, y pairs in the topology's order) and its input speed ω [rad/s]. They
are variants of the topology's nominal linkage (:mod:`vloop.variants`: the numbers change, never the
structure), solved by :func:`vloop.batch.solve` over shared sample times. The batch solves every RRR dyad on
the nominal's branch, so each row goes to a nominal whose branches match the row's coordinates (the side of
each dyad's middle pin, :func:`~vloop.synthesis.linkages.side`); a row whose branches are all the other way is
solved as its mirror image (y → −y, ω → −ω) and reflected back — the motion of a mirrored linkage driven the
other way is the mirror of the motion. So every row moves from its own coordinates, exactly as ``vloop.solve``
of its own file would.

Rows the batch is not sure of (a limit, a possible change point, an ill-conditioned sample) are reported as not
completed rather than solved again one by one (``doubtful="fail"``): a search scores them as infeasible.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..compiler import compile_system
from ..core import batch
from ..core.variants import VariantModel, resolve
from .linkages import Topology, reflect, side

_MODELS: dict[tuple[str, tuple[float, ...]], VariantModel] = {}


@dataclass
class Evaluation:
    """What a population's motion gives: per row, whether the batch solved it all (``completed``) and why not
    (``reason``); (rows, samples) arrays of point positions and velocities (complex) and link angles [rad]."""

    completed: np.ndarray
    reason: list[str]
    points: dict[str, np.ndarray] = field(default_factory=dict)
    velocities: dict[str, np.ndarray] = field(default_factory=dict)
    angles: dict[str, np.ndarray] = field(default_factory=dict)


def evaluate(
    topology: Topology,
    coords: np.ndarray,
    omega: np.ndarray,
    times: np.ndarray,
    *,
    points: tuple[str, ...] = (),
    links: tuple[str, ...] = (),
    rates: bool = False,
) -> Evaluation:
    """Solve a population over ``times`` [s] (strictly increasing, from 0): ``coords`` (V, 2·n_coordinates) the
    t = 0 coordinates, ``omega`` (V,) the input speeds. Returns the positions (and with ``rates`` the velocities)
    of ``points`` and the angles θ of ``links`` at every sample; rows that did not complete hold NaN."""
    coords = np.atleast_2d(np.asarray(coords, float))
    omega = np.asarray(omega, float).reshape(-1)
    times = np.asarray(times, float)
    V, n = len(coords), len(times)
    z = coords[:, 0::2] + 1j * coords[:, 1::2]
    signs = np.stack([side(_named(topology, z), d) for d in topology.dyads], 1) if topology.dyads else np.ones((V, 1))
    mirrored = signs[:, 0] < 0
    key = np.where(mirrored[:, None], -signs, signs)
    ev = Evaluation(np.zeros(V, bool), ["not solved"] * V)
    ev.points = {p: np.full((V, n), np.nan + 0j) for p in points}
    ev.velocities = {p: np.full((V, n), np.nan + 0j) for p in points} if rates else {}
    ev.angles = {k: np.full((V, n), np.nan) for k in links}
    for pattern in np.unique(key, axis=0):
        rows = np.nonzero(np.all(key == pattern, axis=1))[0]
        flip = mirrored[rows]
        zr = np.where(flip[:, None], z[rows].conj(), z[rows])
        values = np.concatenate(
            [
                np.stack([zr.real, zr.imag], 2).reshape(len(rows), -1),
                np.where(flip, -1, 1)[:, None] * omega[rows, None],
            ],
            1,
        )
        _solve_rows(ev, _model(topology, tuple(pattern)), values, rows, flip, times, points, links, rates)
    return ev


def _solve_rows(
    ev: Evaluation,
    model: VariantModel,
    values: np.ndarray,
    rows: np.ndarray,
    flip: np.ndarray,
    times: np.ndarray,
    points: tuple[str, ...],
    links: tuple[str, ...],
    rates: bool,
) -> None:
    """One batch call for the rows of one branch pattern; mirrored rows reflected back into ``ev``."""
    names = [f"{p}.{f}" for p in points for f in (("x", "y", "vx", "vy") if rates else ("x", "y"))]
    names += [f"{k}.theta" for k in links]
    grid = batch.make_grid(model, model.designs(values), times)
    out = batch.solve(model, values, grid, names, doubtful="fail")
    ev.completed[rows] = out.completed
    for i, r in enumerate(rows):
        ev.reason[r] = out.reason[i] if not out.completed[i] else ""
    c = out.columns
    for p in points:
        zp = c[f"{p}.x"] + 1j * c[f"{p}.y"]
        ev.points[p][rows] = np.where(flip[:, None], zp.conj(), zp)
        if rates:
            vp = c[f"{p}.vx"] + 1j * c[f"{p}.vy"]
            ev.velocities[p][rows] = np.where(flip[:, None], vp.conj(), vp)
    for k in links:
        ev.angles[k][rows] = np.where(flip[:, None], -c[f"{k}.theta"], c[f"{k}.theta"])


def _named(topology: Topology, z: np.ndarray) -> dict[str, np.ndarray]:
    return {name: z[:, i] for i, name in enumerate(topology.coordinates)}


def _model(topology: Topology, pattern: tuple[float, ...]) -> VariantModel:
    """The variant model of the topology's nominal linkage on the branches ``pattern`` (compiled once)."""
    key = (topology.name + "/" + ",".join(topology.coordinates), pattern)
    if key not in _MODELS:
        nominal = dict(topology.nominal)
        for d, s in zip(topology.dyads, pattern, strict=False):
            if side({k: np.array(v) for k, v in nominal.items()}, d) != s:
                nominal[d[1]] = reflect(nominal[d[1]], nominal[d[0]], nominal[d[2]])
        mech = topology.mechanism(nominal, name=f"nominal-{topology.name}", omega=1.0, times=np.array([0.0, 1.0]))
        names = [
            f"{'points' if c in topology.points else 'joints'}.{c}.{f}" for c in topology.coordinates for f in "xy"
        ]
        names.append(f"drivers.{topology.input}.omega")
        refs = tuple(resolve(mech, name, "synthesis") for name in names)
        _MODELS[key] = VariantModel.build(mech, compile_system(mech), refs)
    return _MODELS[key]
