"""MuJoCo as an engine: the exported MJCF (:mod:`validators.models.mjcf`) simulated under its driver.

Engine name ``"mujoco"``. The model is the one ``vloop export --format mjcf`` writes (one construction);
this module assembles it at t = 0 and runs MuJoCo's own time integration:

* assembly (:func:`assemble`): Newton on MuJoCo's constraint rows — the cut pins' ``connect`` residuals
  ``efc_pos`` with their Jacobian ``efc_J`` — and on the input's tendon (its set value), from the file's
  coordinates (qpos = 0); rates from the same rows (``J·q̇ = [0; ẋ]``), so the simulation starts consistent;
* simulation (:func:`solve`): ``mj_step`` (implicitfast) with the servo's set point and its rate set from the
  driver at every step, the step such that each sample falls on one (at most the model's timestep);
* outputs: θ and ω of every body (``xmat``, ``mj_objectVelocity``), x, y, vx, vy of every joint and tracer point
  (its sites), s and v of every slider (its block's site against the guide's axis). No accelerations: a soft
  constraint's accelerations carry its impedance's transient, and MuJoCo's reported ``qacc`` is that of the step.

Accuracy (the tolerance, :data:`TOLERANCE`): the engine reports its own error per sample in ``health`` —
``violation``, the largest cut-pin gap (``efc_pos``), and ``lag``, the servo's error on the input, each as a
fraction of the mechanism's size — and the comparison allows what the solver's settings bound
(see :func:`allowance`).
"""

from __future__ import annotations

import collections
import math
from typing import Any

import numpy as np

from vloop.drivers import evaluate_all
from vloop.errors import MechanismError, MotionError
from vloop.mechanism import Mechanism
from vloop.result import Result

from .models.mjcf import Layout, build

ENGINE = "mujoco"
# The run stops where the mechanism cannot follow: a cut-pin gap or an input lag beyond 1e-3 (of the size, or rad).
# At a limit position the servo can no longer turn the input: the lag jumps to ~1 rad within one sample. Below
# that, every sample's reported gap and lag are part of its allowance (:func:`allowance`).
LOST = 1e-3
ASSEMBLY_TOL = 1e-13  # Newton's assembly: largest cut-pin gap, fraction of the size (round-off is ~1e-16)


WARNINGS: collections.deque[str] = collections.deque(maxlen=100)  # MuJoCo's last warnings


def quiet() -> None:
    """Keep MuJoCo's warnings in :data:`WARNINGS` (its default prints them and writes MUJOCO_LOG.TXT into the
    working folder; a run writes nothing outside its output folder). An unstable simulation is caught by the
    run's own gap and lag."""
    import mujoco

    mujoco.set_mju_user_warning(WARNINGS.append)


def load(mech: Mechanism) -> tuple[Any, Any, Layout]:
    """(MjModel, MjData, Layout) of ``mech`` from its MJCF text."""
    import mujoco

    quiet()
    text, layout = build(mech)
    model = mujoco.MjModel.from_xml_string(text)
    return model, mujoco.MjData(model), layout


class _Rows:
    """The constraint rows the assembly solves: the cuts' ``connect`` rows (x, y) and one row per input."""

    def __init__(self, model: Any, layout: Layout) -> None:
        import mujoco

        self.mujoco = mujoco
        self.model, self.layout = model, layout
        self.tendon = np.zeros((len(layout.tendons), model.nv))
        for i, coef in enumerate(layout.tendons):
            for j, c in coef.items():
                self.tendon[i, model.jnt_dofadr[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, j)]] = c

    def equality(self, data: Any) -> tuple[np.ndarray, np.ndarray]:
        """(gaps, Jacobian) of the cut pins at data.qpos [m]: each connect's x and y rows (z is 0 in the plane)."""
        m = self.model
        self.mujoco.mj_forward(m, data)
        rows = np.flatnonzero(data.efc_type == self.mujoco.mjtConstraint.mjCNSTR_EQUALITY)
        rows = rows[np.arange(len(rows)) % 3 != 2]
        jac = data.efc_J.reshape(-1, m.nv)[rows] if data.nefc else np.zeros((0, m.nv))
        return data.efc_pos[rows].copy(), jac.copy()


def _targets(mech: Mechanism, layout: Layout, x: np.ndarray) -> np.ndarray:
    """The inputs x (θ [rad], s [file units]) as tendon lengths (θ − θ(0) [rad], (s − s(0))·k [m])."""
    k = np.array([1.0 if d.kind == "crank" else layout.scale for d in mech.drivers])
    return (x - np.asarray(layout.offsets)) * k


def assemble(model: Any, data: Any, layout: Layout, mech: Mechanism, t: float) -> float:
    """Close the cut pins with the inputs at their values at ``t`` (Newton from qpos = 0, the input moved there
    by continuation from the coordinates' value); sets qpos, qvel, act and ctrl; returns the gap left [m]."""
    rows = _Rows(model, layout)
    x, xd, _ = (a[0] for a in evaluate_all(mech, np.array([t])))
    target = _targets(mech, layout, x)
    size = mech.scale * layout.scale
    data.qpos[:] = 0.0
    data.qvel[:] = 0.0
    steps = max(1, math.ceil(float(np.max(np.abs(target), initial=0.0)) / 0.2))
    for s in range(1, steps + 1):
        goal = target * s / steps
        for _ in range(50):
            gap, jac = rows.equality(data)
            r = np.concatenate([gap, rows.tendon @ data.qpos - goal])
            a = np.vstack([jac, rows.tendon])
            dq = np.linalg.lstsq(a, -r, rcond=None)[0]
            data.qpos[:] += dq
            if np.max(np.abs(dq), initial=0.0) < 1e-15 * max(size, 1.0) and s == steps:
                break
            if np.max(np.abs(r), initial=0.0) < 1e-3 * ASSEMBLY_TOL * size and s < steps:
                break
    gap, jac = rows.equality(data)
    if np.max(np.abs(gap), initial=0.0) > ASSEMBLY_TOL * size:
        raise MechanismError(
            f"{mech.name}: mujoco cannot assemble the mechanism at t = {t:g} s "
            f"(cut-pin gap {np.max(np.abs(gap)) / size:.3g} of its size)"
        )
    k = np.array([1.0 if d.kind == "crank" else layout.scale for d in mech.drivers])
    a = np.vstack([jac, rows.tendon])
    data.qvel[:] = np.linalg.lstsq(a, np.concatenate([np.zeros(len(gap)), xd * k]), rcond=None)[0]
    set_inputs(data, target, xd * k)
    return float(np.max(np.abs(gap), initial=0.0))


def set_inputs(data: Any, target: np.ndarray, rate: np.ndarray, lead: np.ndarray | float = 0.0) -> None:
    """The servos' set points (activations) and rates (ctrl): actuators 2i and 2i + 1 drive input i. ``lead``:
    the set point's lead ẍ/ω_n², which makes the servo's stiffness give the flywheel's torque armature·ẍ."""
    n = len(target)
    data.act[:n] = target + lead
    data.ctrl[0 : 2 * n : 2] = rate  # the set point moves at the input's speed between two settings
    data.ctrl[1 : 2 * n : 2] = rate


def solve(mechanism: Mechanism, times: np.ndarray | None = None, **options: Any) -> Result:
    """θ, ω of every body, x, y, vx, vy of every point, s, v of every slider over ``times`` [s] (default: the
    file's), by MuJoCo's simulation of the exported model under its driver. MotionError where it stops."""
    mech = mechanism
    t = np.asarray(mech.times if times is None else times, float)
    model, data, layout = load(mech)
    t0 = 0.0 if not len(t) else min(0.0, float(t[0]))
    assemble(model, data, layout, mech, t0)
    return simulate(model, data, layout, mech, t, t0)


def simulate(model: Any, data: Any, layout: Layout, mech: Mechanism, t: np.ndarray, t0: float = 0.0) -> Result:
    """Run the model from its state in ``data`` at ``t0`` [s] through the samples ``t``, the servos set from the
    driver at every step (at most the model's timestep, each sample on a step)."""
    import mujoco

    quiet()
    h_max = float(model.opt.timestep)
    reader = _Reader(model, mech, layout)
    rows: list[dict[str, float]] = []
    health: dict[str, list[float]] = {"violation": [], "lag": []}
    units = np.array([1.0 if d.kind == "crank" else layout.scale for d in mech.drivers])
    now = t0
    for k, tk in enumerate(t):
        n = max(1, math.ceil((tk - now) / h_max * (1 - 1e-12))) if tk > now else 0
        if n:
            h = (tk - now) / n
            model.opt.timestep = h
            grid = now + h * np.arange(n)
            x, _, xdd = evaluate_all(mech, grid)
            _, xd, _ = evaluate_all(mech, grid + 0.5 * h)  # the set point's speed over the step: its mean
            targets = _targets(mech, layout, x)
            rates, leads = xd * units, xdd * units / layout.omega**2
            for i in range(n):
                set_inputs(data, targets[i], rates[i], leads[i])
                mujoco.mj_step(model, data)
            now = float(tk)
        mujoco.mj_forward(model, data)
        row, gap, lag = reader.read(data, _targets(mech, layout, evaluate_all(mech, np.array([tk]))[0][0]))
        if not all(math.isfinite(v) for v in row.values()) or gap > LOST or lag > LOST:
            raise MotionError(
                f"{mech.name}: mujoco cannot follow the input at sample {k}, t = {tk:g} s (cut-pin gap {gap:.3g} of "
                f"its size, input lag {lag:.3g}): a limit position, or the loops cannot close",
                time=float(tk),
                sample=k,
                partial=_result(mech, t[:k], rows, health, reader),
            )
        rows.append(row)
        health["violation"].append(gap)
        health["lag"].append(lag)
    model.opt.timestep = h_max
    return _result(mech, t, rows, health, reader)


class _Reader:
    """Reads a sample's outputs from MjData, in the file's units."""

    def __init__(self, model: Any, mech: Mechanism, layout: Layout) -> None:
        import mujoco

        self.mujoco, self.model, self.mech, self.layout = mujoco, model, mech, layout
        self.k = layout.scale
        name = lambda kind, n: mujoco.mj_name2id(model, kind, n)  # noqa: E731
        self.body = {b: name(mujoco.mjtObj.mjOBJ_BODY, b) for b in mech.moving_links}
        self.site = {p: name(mujoco.mjtObj.mjOBJ_SITE, f"{mech.body_of_point(p)}/{p}") for p in mech.tracked_points}
        bodies = mech.bodies()
        self.slider = {}
        for s, sl in mech.sliders.items():
            g = bodies[sl.guide]
            c, sn = math.cos(g.theta0), math.sin(g.theta0)
            u_local = np.array([c * sl.axis[0] + sn * sl.axis[1], -sn * sl.axis[0] + c * sl.axis[1]])
            guide = name(mujoco.mjtObj.mjOBJ_BODY, sl.guide) if sl.guide != mech.ground else 0
            self.slider[s] = (guide, u_local, name(mujoco.mjtObj.mjOBJ_SITE, f"{s}/{sl.joint}"))
        self.rows = _Rows(model, layout)
        self.theta0 = {b: bodies[b].theta0 for b in mech.moving_links}

    def read(self, data: Any, target: np.ndarray) -> tuple[dict[str, float], float, float]:
        """(the sample's columns, cut-pin gap / size, input lag [rad, or / size])."""
        mj, m, k = self.mujoco, self.model, self.k
        out: dict[str, float] = {}
        v6 = np.zeros(6)
        for b, i in self.body.items():
            xm = data.xmat[i]
            out[f"{b}.theta"] = math.atan2(xm[3], xm[0])
            mj.mj_objectVelocity(m, data, mj.mjtObj.mjOBJ_BODY, i, v6, 0)
            out[f"{b}.omega"] = float(v6[2])
        for p, i in self.site.items():
            out[f"{p}.x"], out[f"{p}.y"] = (float(c) / k for c in data.site_xpos[i][:2])
            mj.mj_objectVelocity(m, data, mj.mjtObj.mjOBJ_SITE, i, v6, 0)
            out[f"{p}.vx"], out[f"{p}.vy"] = float(v6[3]) / k, float(v6[4]) / k
        for s, (g, u_local, site) in self.slider.items():
            rg = data.xmat[g].reshape(3, 3)[:2, :2]
            u = rg @ u_local
            org = data.xpos[g][:2] if g else np.zeros(2)
            r = data.site_xpos[site][:2] - org
            mj.mj_objectVelocity(m, data, mj.mjtObj.mjOBJ_SITE, site, v6, 0)
            vp = v6[3:5].copy()
            vg = np.zeros(6)
            if g:
                mj.mj_objectVelocity(m, data, mj.mjtObj.mjOBJ_XBODY, g, vg, 0)  # at the frame's origin
            w = vg[2]
            out[f"{s}.s"] = float(r @ u) / k
            out[f"{s}.v"] = float((vp - vg[3:5]) @ u + w * (r @ np.array([-u[1], u[0]]))) / k
        gap, _ = self.rows.equality(data)
        size = self.mech.scale * k
        lag = np.abs(self.rows.tendon @ data.qpos - target)
        lag = lag / np.array([1.0 if d.kind == "crank" else size for d in self.mech.drivers])
        return out, float(np.max(np.abs(gap), initial=0.0)) / size, float(np.max(lag, initial=0.0))


def _result(
    mech: Mechanism, t: np.ndarray, rows: list[dict[str, float]], health: dict[str, list[float]], reader: _Reader
) -> Result:
    n = len(rows)
    names = list(rows[0]) if rows else []
    cols = {c: np.array([r[c] for r in rows]) for c in names}
    for b in reader.body:
        if n:
            raw, w = cols[f"{b}.theta"], cols[f"{b}.omega"]
            pred = 0.5 * (w[1:] + w[:-1]) * np.diff(t[:n])
            inc = pred + (np.diff(raw) - pred + math.pi) % (2 * math.pi) - math.pi
            th0 = reader.theta0[b]
            start = th0 + (raw[0] - th0 + math.pi) % (2 * math.pi) - math.pi
            cols[f"{b}.theta"] = start + np.concatenate(([0.0], np.cumsum(inc)))
    hl = {k: np.asarray(v[:n], float) for k, v in health.items()}
    return Result(mech.name, ENGINE, np.asarray(t[:n], float), cols, hl, {"allowance": allowance(mech, hl, cols)})


def allowance(mech: Mechanism, health: dict[str, np.ndarray], cols: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Per sample and group, the error the run itself reports: the cut-pin gap (a fraction of the size) and the
    input's lag (rad, or a fraction of the size) carried through the linkage's largest velocity ratio. Positions:
    (gap + lag·ratio)·size; angles: gap·size/ℓ + lag·ratio, ℓ the shortest distance between two joints of a body."""
    gap = np.asarray(health.get("violation", []), float)
    lag = np.asarray(health.get("lag", []), float)
    ratio = _ratio(mech, cols)
    pos = (gap + lag * ratio) * mech.scale
    ang = gap * mech.scale / _shortest(mech) + lag * ratio
    return {"position": pos, "angle": ang}


def _shortest(mech: Mechanism) -> float:
    """The shortest distance between two joints of one body (the size where a body has one joint)."""
    out = mech.scale
    for b in mech.bodies().values():
        pts = np.array(list(b.local.values()), float)
        if len(pts) > 1:
            d = np.hypot(*(pts[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
            d = d[d > 0]
            out = min(out, float(d.min())) if d.size else out
    return out


def _ratio(mech: Mechanism, cols: dict[str, np.ndarray]) -> float:
    """The largest rate of any output per unit rate of the input over the run (dimensionless, lengths per size)."""
    omegas = [np.abs(v) for c, v in cols.items() if c.endswith(".omega")]
    speeds = [np.abs(v) / mech.scale for c, v in cols.items() if c.endswith((".vx", ".vy", ".v"))]
    peak = max((float(np.max(a)) for a in omegas + speeds if a.size), default=1.0)
    inputs = [
        np.abs(cols[f"{d.target}.omega"]) for d in mech.drivers if d.kind == "crank" and f"{d.target}.omega" in cols
    ]
    base = max((float(np.max(a)) for a in inputs if a.size), default=0.0)
    return peak / base if base > 0 else 1.0
