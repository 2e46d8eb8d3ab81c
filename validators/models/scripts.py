"""Standalone Python scripts of a mechanism's Pinocchio and Exudyn models (``vloop export --format pinocchio|exudyn``).

One implementation: a script is made of the validators' own source, copied verbatim at export time — the model
construction (:func:`validators.pinocchio.build_model` and its tree plan; :func:`validators.exudyn_model.build`)
and the numerics the engines run on it (Pinocchio's Newton projection and continuation, ``_Solver``; Exudyn's
Newton on its own constraint equations, ``_Kinematics``) — with the inputs as vloop evaluates them
(:mod:`vloop.drivers`, copied too) and the mechanism as a data literal read by
:mod:`validators.models.description`'s classes. A script needs numpy and the engine's package (scipy too for a
tabulated input), not vloop; it runs over the file's times and writes ``t`` and every body's θ, ω, α, every
point's x, y, vx, vy, ax, ay and every slider's s, v, a as CSV (the file's units, radians, seconds), the columns
vloop's own CSV has.
"""

from __future__ import annotations

import ast
import inspect
import pprint
import textwrap
from types import ModuleType
from typing import Any

from vloop.mechanism import Mechanism

from . import description

HEADER = '''#!/usr/bin/env python3
"""{title}: {what}, standalone.

Written by ``vloop export --format {fmt}`` from {source}. Run it as

    python {script} [--out FILE.csv]

It needs numpy and {needs}; it does not need vloop. It builds the model vloop's validators build (their code is
copied below verbatim), runs it over the file's times and writes the trajectory as CSV: t [s], then every body's
theta, omega, alpha [rad, rad/s, rad/s²], every joint and point's x, y, vx, vy, ax, ay and every slider's s, v, a
(lengths in {units}).

Sections: 1. the mechanism as data (change it here: bodies in their frames at t = 0, drivers, times);
2. the description classes and the inputs x(t) as vloop evaluates them; 3. the model and the engine's numerics
(from the validators); 4. the run.
"""

from __future__ import annotations

import argparse
import csv
import functools
import itertools
import math
import sys
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

'''


def _segments(module: ModuleType, names: list[str] | None = None, leave: tuple[str, ...] = ()) -> str:
    """The source of a module's top-level definitions and assignments (all, or those ``names``; never those in
    ``leave``), in file order; never its docstring or imports."""
    src = inspect.getsource(module)
    tree = ast.parse(src)
    out = []
    for node in tree.body:
        if isinstance(node, (ast.Import, ast.ImportFrom)) or (
            isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)
        ):
            continue
        if (names is not None and _name(node) not in names) or _name(node) in leave:
            continue
        seg = ast.get_source_segment(src, node, padded=True) or ""
        deco = "".join(f"@{ast.get_source_segment(src, d)}\n" for d in getattr(node, "decorator_list", []))
        out.append(deco + textwrap.dedent(seg))
    missing = set(names or ()) - {_name(n) for n in tree.body}
    if missing:
        raise KeyError(f"{module.__name__} has no {', '.join(sorted(missing))}")
    return "\n\n".join(out)


def _name(node: ast.stmt) -> str | None:
    if isinstance(node, (ast.FunctionDef, ast.ClassDef, ast.AsyncFunctionDef)):
        return node.name
    if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name):
        return node.targets[0].id
    if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
        return node.target.id
    return None


def _common(mech: Mechanism) -> str:
    """Sections 1 and 2: the data, the description classes, vloop's input functions."""
    import vloop.drivers as drivers

    from .. import forces_common

    data = pprint.pformat(description.describe(mech), width=116, sort_dicts=False, compact=True)
    return "\n\n".join(
        [
            "# ---------------------------------------------------------------- 1. the mechanism (the file's t = 0)",
            f"DATA = {data}",
            "# ---------------------------------------------------------------- 2. description and inputs",
            'class MechanismError(ValueError):\n    """The mechanism cannot be modelled or assembled."""\n\n'
            "    def __init__(self, message: str, **where: Any) -> None:\n        super().__init__(message)",
            _segments(
                description, ["Body", "Slider", "Profile", "Driver", "LoadProfile", "Load", "Mechanism", "from_data"]
            ),
            "# the file's masses and loads, as the validators' force engines read them (validators/forces_common.py)",
            "def mass_table(mech: Mechanism) -> dict[str, tuple[float, np.ndarray, float]]:\n"
            '    """body -> (mass [kg], centre of mass in the body frame [length], inertia about it [kg·m²])."""\n'
            "    return mech.masses_table",
            'def factor(mech: Mechanism) -> float:\n    """Metres per length unit."""\n    return mech.length_factor',
            _segments(forces_common, ["load_series"]),
            "# the inputs x(t), ẋ(t), ẍ(t), as every engine of vloop evaluates them (vloop/drivers.py)",
            _segments(drivers),
            "MECHANISM = from_data(DATA)",
        ]
    )


FOOTER = '''

def write_csv(path: str, t: np.ndarray, columns: dict[str, np.ndarray]) -> None:
    """t and every column, one row per solved sample."""
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["t", *columns])
        for k in range(len(t)):
            w.writerow([repr(float(t[k])), *(repr(float(c[k])) for c in columns.values())])


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="{csv}", help="the CSV file to write (default: %(default)s)")
    args = parser.parse_args()
    t, columns, stopped = run(MECHANISM, MECHANISM.times)
    write_csv(args.out, t, columns)
    print(f"{{MECHANISM.name}}: {{len(t)}} of {{len(MECHANISM.times)}} samples written to {{args.out}}"
          + (f" (stopped: {{stopped}})" if stopped else ""))
    sys.exit(1 if stopped else 0)
'''


PINOCCHIO_RUN = '''

# ---------------------------------------------------------------- 4. the run


def run(mech: Mechanism, times: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray], str]:
    """(times solved, columns, why it stopped or ""): the validators' continuation sample after sample."""
    import pinocchio as pin

    pm = build_model(mech)
    if mech.masses_table or mech.gravity:
        _add_dynamics(pm, mech)  # the file's inertias and gravity (Pinocchio's dynamics; the kinematics ignore them)
    solver = _Solver(pm, NEWTON_TOL, MAX_ITER, MAX_BISECT, MAX_COND)
    inputs = _inputs_fn(mech)
    t_a = _assembly_time(mech)
    state = _assemble(solver, t_a, inputs)
    states, stopped = [], ""
    step = float(np.median(np.diff(times))) if len(times) > 1 else 1.0
    for k, tk in enumerate(times):
        try:
            n_min = math.ceil(abs(tk - t_a) / step) if k == 0 else 1
            state = solver.march(state, float(tk), inputs, max(n_min, 1))
        except _NoConvergence as exc:
            stopped = f"sample {k} at t = {tk:g} s: {exc}"
            break
        states.append(state)
    m, d, w = pm.model, solver.w.data, solver.w
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    cols: dict[str, list[float]] = {}
    for st in states:
        pin.forwardKinematics(m, d, st.q, st.v, st.a)
        pin.updateFramePlacements(m, d)
        for b in mech.moving_links:
            f = pm.body_frame[b]
            vel, acc = pin.getFrameVelocity(m, d, f, lwa), pin.getFrameClassicalAcceleration(m, d, f, lwa)
            for c, v in zip(("theta", "omega", "alpha"), (w._angle(f), vel.angular[2], acc.angular[2])):
                cols.setdefault(f"{b}.{c}", []).append(float(v))
        for p in mech.tracked_points:
            f = pm.point_frame[p]
            xy = d.oMf[f].translation[:2]
            v, a = pin.getFrameVelocity(m, d, f, lwa).linear, pin.getFrameClassicalAcceleration(m, d, f, lwa).linear
            for c, val in zip(("x", "y", "vx", "vy", "ax", "ay"), (xy[0], xy[1], v[0], v[1], a[0], a[1])):
                cols.setdefault(f"{p}.{c}", []).append(float(val))
        for s in mech.sliders:
            for c, val in zip(("s", "v", "a"), w.slider_sva(pm.slider_rows[s])):
                cols.setdefault(f"{s}.{c}", []).append(float(val))
    t = np.asarray(times[: len(states)], float)
    out = {k: np.asarray(v) for k, v in cols.items()}
    for b in mech.moving_links:
        if len(t):
            out[f"{b}.theta"] = _continuous_angle(out[f"{b}.theta"], out[f"{b}.omega"], t, pm.bodies[b].theta0)
    return t, out, stopped
'''

EXUDYN_RUN = '''

# ---------------------------------------------------------------- 4. the run


def run(mech: Mechanism, times: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray], str]:
    """(times solved, columns, why it stopped or ""): Newton on Exudyn's constraint equations, continued from
    the t = 0 assembly sample after sample (the validators' exudyn-kinematic engine)."""
    model = build_with_loads(mech) if (mech.masses_table or mech.gravity or mech.loads) else build(mech)
    kin = _Kinematics(model)
    for inp in model.driver_inputs:
        inp.prefetch(np.asarray(times, float))
    t0 = 0.0
    for inp in model.driver_inputs:
        if inp.driver.profile is not None and inp.driver.profile.t[0] > 0:
            t0 = max(t0, float(inp.driver.profile.t[0]))
    q, ok, it = kin.newton(np.zeros(kin.n), t0, max_iter=100, damped=True)
    if not ok:
        raise MechanismError(f"{mech.name}: Newton on Exudyn's constraints did not assemble it at t = {t0:g} s")
    state = kin.state(q, t0, it)
    states, stopped = [], ""
    for k, tk in enumerate(times):
        nxt = kin.advance(state, float(tk), 14) if tk != state.t else state
        if nxt is None:
            stopped = f"sample {k} at t = {tk:g} s: no continuation on this branch"
            break
        state = nxt
        states.append(state)
    Q = np.array([s.q for s in states]).reshape(len(states), kin.n) + model.reference_vector()
    QD = np.array([s.qd for s in states]).reshape(len(states), kin.n)
    QDD = np.array([s.qdd for s in states]).reshape(len(states), kin.n)
    out: dict[str, np.ndarray] = {}
    for b in mech.moving_links:
        i = model.moving[b].ode2[2]
        out[f"{b}.theta"], out[f"{b}.omega"], out[f"{b}.alpha"] = Q[:, i], QD[:, i], QDD[:, i]

    def point(body: str, local: Any) -> tuple[np.ndarray, ...]:
        n = len(states)
        if body not in model.moving:
            z = np.zeros(n)
            return z + local[0], z + local[1], z, z, z, z
        c = model.local_rel_com(body, local)
        i = model.moving[body].ode2
        th, om, al = Q[:, i[2]], QD[:, i[2]], QDD[:, i[2]]
        rx, ry = np.cos(th) * c[0] - np.sin(th) * c[1], np.sin(th) * c[0] + np.cos(th) * c[1]
        return (Q[:, i[0]] + rx, Q[:, i[1]] + ry, QD[:, i[0]] - om * ry, QD[:, i[1]] + om * rx,
                QDD[:, i[0]] - al * ry - om * om * rx, QDD[:, i[1]] + al * rx - om * om * ry)

    for p in mech.tracked_points:
        b = mech.body_of_point(p)
        for c, v in zip(("x", "y", "vx", "vy", "ax", "ay"), point(b, model.bodies[b].local[p])):
            out[f"{p}.{c}"] = v
    for s, sl in mech.sliders.items():
        P, O = point(s, (0.0, 0.0)), point(sl.guide, (0.0, 0.0))
        g = model.bodies[sl.guide]
        u0 = rot(g.theta0).T @ np.asarray(sl.axis, float)
        if sl.guide in model.moving:
            i = model.moving[sl.guide].ode2[2]
            th, om, al = Q[:, i], QD[:, i], QDD[:, i]
        else:
            th = om = al = np.zeros(len(states))
        ux, uy = np.cos(th) * u0[0] - np.sin(th) * u0[1], np.sin(th) * u0[0] + np.cos(th) * u0[1]
        dx, dy, dvx, dvy, dax, day = (P[j] - O[j] for j in range(6))
        out[f"{s}.s"] = dx * ux + dy * uy
        out[f"{s}.v"] = dvx * ux + dvy * uy + om * (dy * ux - dx * uy)  # u̇ = ω (−u_y, u_x)
        out[f"{s}.a"] = (dax * ux + day * uy + 2 * om * (dvy * ux - dvx * uy)
                         + dx * (-al * uy - om * om * ux) + dy * (al * ux - om * om * uy))
    return np.asarray(times[: len(states)], float), out, stopped
'''


def pinocchio_script(mech: Mechanism, script: str, source: str) -> str:
    """The Pinocchio script of ``mech`` (``script``: its file name, ``source``: where the mechanism came from)."""
    from .. import pinocchio, pinocchio_forces

    names = [
        "_wrap",
        "TWO_PI",
        "Edge",
        "TreePlan",
        "_UnionFind",
        "plan_tree",
        "_se3",
        "_pose",
        "_Row",
        "PinocchioModel",
        "build_model",
        "_slider_row",
        "_Work",
        "Inputs",
        "RESIDUAL_TOL",
        "MAX_CRANK_STEP",
        "MAX_SLIDER_STEP",
        "CROSS_JUMP",
        "JUMP_RATIO",
        "JUMP_FLOOR",
        "MAX_BISECT",
        "NEWTON_TOL",
        "MAX_ITER",
        "MAX_COND",
        "_NoConvergence",
        "_State",
        "_cond2",
        "CERTAIN_COND",
        "_well_conditioned",
        "_Solver",
        "_inputs_fn",
        "_assembly_time",
        "_assemble",
        "_continuous_angle",
    ]
    model = "\n\n".join(
        [
            "# ---------------------------------------------------------------- 3. the model and its numerics",
            "# (validators/pinocchio.py, verbatim)",
            _segments(pinocchio, names),
            "# the file's inertias and gravity (validators/pinocchio_forces.py)",
            _segments(pinocchio_forces, ["_add_dynamics"]),
        ]
    )
    return _script(mech, script, source, "pinocchio", "Pinocchio (pip install pin)", model, PINOCCHIO_RUN)


# what only the time integration uses (the script solves the kinematics): Exudyn-evaluated formula inputs
DYNAMIC_ONLY = ("OFFSET_FUNCTIONS", "formula_offsets", "_formula", "_object_index")


def exudyn_script(mech: Mechanism, script: str, source: str) -> str:
    """The Exudyn script of ``mech``: validators/exudyn_model.py's construction, validators/exudyn.py's Newton."""
    from .. import exudyn, exudyn_forces, exudyn_model

    names = [
        "FD_TURN",
        "_FD_OFFSETS",
        "_FD_WEIGHTS",
        "MAX_MOVE",
        "JUMP_RATIO",
        "JUMP_FLOOR",
        "_settings",
        "ConstraintEquations",
        "_State",
        "_Kinematics",
    ]
    model = "\n\n".join(
        [
            "# ---------------------------------------------------------------- 3. the model and its numerics",
            "# (validators/exudyn_model.py and the kinematic engine of validators/exudyn.py, verbatim)",
            _segments(exudyn_model, leave=DYNAMIC_ONLY),
            "em = sys.modules[__name__]  # the engine's code names the model module 'em'",
            _segments(exudyn, names),
            "# the file's masses, gravity and loads (validators/exudyn_forces.py; its build is build_with_loads here)",
            _segments(exudyn_forces, ["_force_function", "_torque_function"]),
            _segments(exudyn_forces, ["build"]).replace("def build(", "def build_with_loads(", 1),
        ]
    )
    return _script(mech, script, source, "exudyn", "Exudyn (pip install exudyn)", model, EXUDYN_RUN)


def _script(mech: Mechanism, script: str, source: str, fmt: str, needs: str, model: str, run: str) -> str:
    """A whole script: the header, the mechanism as data, the engine's ``model`` code, its ``run`` and the footer."""
    engine = {"pinocchio": "Pinocchio", "exudyn": "Exudyn"}[fmt]
    head = HEADER.format(
        title=mech.title or mech.name,
        what=f"the {engine} model vloop's validators build",
        fmt=fmt,
        source=source,
        script=script,
        needs=needs,
        units=mech.units,
    )
    return head + _common(mech) + "\n\n\n" + model + run + FOOTER.format(csv=_csv_name(script))


def _csv_name(script: str) -> str:
    return script.rsplit(".", 1)[0] + ".csv"


def check(text: str) -> Any:
    """The script compiled (SyntaxError otherwise): the exporter never writes a script Python cannot read."""
    return compile(text, "<vloop export>", "exec")
