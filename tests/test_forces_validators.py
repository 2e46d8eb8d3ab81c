"""vloop's forces against Pinocchio and Exudyn, which compute them their own way from the same file.

* Pinocchio (validators/pinocchio_forces.py): inverse dynamics of the cut tree plus the loop-closure
  multipliers, τ = M(q)·q̈ + h(q, q̇) − J_cᵀ·λ, solved for λ and the driver torques;
* Exudyn kinematic (validators/exudyn_forces.py): Exudyn's mass matrix and right-hand side at its own
  kinematic solution, C_qᵀ·λ = f − M·q̈;
* Exudyn dynamic: the multipliers of Exudyn's generalized-α time integration (its joint reactions).

Tolerances (|a − b| ≤ rtol·peak + floor·group peak, vloop.compare): Pinocchio and Exudyn kinematic
1e-9 (measured ≤ 1e-12 of each quantity's peak over the catalog with masses); Exudyn dynamic 2e-5
(validators/tolerances.py; measured ≤ 2e-6 of the group peak on the catalog files with masses).
Every catalog file is also checked with masses, centres of mass off the link lines, gravity, a
point load and a torque added (moving guides, ternary links, order-3 pins, two cranks, Newton
blocks), and the eight-bar driven at its slider.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import vloop
from validators import exudyn_forces, pinocchio_forces
from validators.tolerances import tolerance
from vloop.compare import assert_histories_close
from vloop.forces import solve_forces

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
WITH_MASSES = sorted(p.stem for p in MECH.glob("*.toml") if vloop.load(p).masses)
ALL = sorted(p.stem for p in MECH.glob("*.toml"))


def with_masses(stem: str) -> vloop.Mechanism:
    """A catalog file with masses on every moving body (centres of mass off the joints' mean), gravity,
    a point force at the last joint/point of a moving body and a torque on the last body."""
    mech = vloop.load(MECH / f"{stem}.toml")
    data = vloop.mechanism.to_dict(mech)
    rng = np.random.default_rng(sum(map(ord, stem)))
    for name, table in data["links"].items():
        if not table.get("ground"):
            mean = np.mean([mech.joints[j] for j in mech.links[name].joints], axis=0)
            com = mean + rng.normal(size=2) * 0.1 * mech.scale
            table.update(mass=float(rng.uniform(0.5, 3)), inertia=float(rng.uniform(0.01, 1)), com=com.tolist())
    for name, table in data.get("sliders", {}).items():
        com = np.asarray(mech.joints[mech.sliders[name].joint]) + 0.05 * mech.scale
        table.update(mass=float(rng.uniform(0.5, 2)), inertia=0.3, com=com.tolist())
    data["gravity"] = [0.3, -9.81]
    moving = [j for j in mech.joints if any(b != mech.ground for b in mech.bodies_at(j))]
    data["loads"] = [
        {"point": (list(mech.points) or moving)[-1], "force": [10.0, -5.0]},
        {"link": mech.moving_links[-1], "torque": 3.0},
    ]
    return vloop.from_dict(data, source=f"{stem}+masses", base_dir=MECH)


def vloop_forces(mech: vloop.Mechanism) -> tuple[vloop.Result, object]:
    try:
        res = vloop.solve(mech)
    except vloop.MotionError as exc:  # a run to a limit position: the samples solved
        res = exc.partial
    return res, solve_forces(mech, res)


def agree(engine_forces, reference, rtol, floor=1e-12) -> None:
    n = min(len(engine_forces), len(reference))
    assert n > 0
    assert_histories_close(
        engine_forces.head(n).as_result(), reference.head(n).as_result(), rtol, floor=floor,
        min_columns=len(reference.columns),
    )  # fmt: skip


def engine_partial(solve, mech, times):
    try:
        return solve(mech, times)
    except vloop.MotionError as exc:
        return exc.partial


@pytest.mark.parametrize("stem", WITH_MASSES)
def test_pinocchio_catalog_files_with_masses(stem: str) -> None:
    mech = vloop.load(MECH / f"{stem}.toml")
    res, forces = vloop_forces(mech)
    kin, pin_forces = pinocchio_forces.solve_with_forces(mech, res.t)
    assert kin.engine == pin_forces.engine == "pinocchio"
    agree(pin_forces, forces, rtol=1e-9)


@pytest.mark.parametrize("stem", WITH_MASSES)
def test_exudyn_kinematic_catalog_files_with_masses(stem: str) -> None:
    mech = vloop.load(MECH / f"{stem}.toml")
    res, forces = vloop_forces(mech)
    _, exu_forces = exudyn_forces.solve_with_forces(mech, res.t, mode="kinematic")
    agree(exu_forces, forces, rtol=1e-9)


@pytest.mark.parametrize("stem", ["slider_crank_engine", "fourbar_textbook_dynamics"])
def test_exudyn_dynamic_multipliers(stem: str) -> None:
    mech = vloop.load(MECH / f"{stem}.toml")
    res, forces = vloop_forces(mech)
    _, exu_forces = exudyn_forces.solve_with_forces(mech, res.t, mode="dynamic")
    tol = tolerance("exudyn-dynamic", "vloop")
    agree(exu_forces, forces, rtol=tol.rtol, floor=tol.floor)


@pytest.mark.parametrize("stem", ALL)
def test_every_catalog_file_with_masses_and_loads(stem: str) -> None:
    mech = with_masses(stem)
    res, forces = vloop_forces(mech)
    pin_forces = engine_partial(pinocchio_forces.solve_with_forces, mech, res.t)[1]
    agree(pin_forces, forces, rtol=1e-9)
    exu_forces = engine_partial(lambda m, t: exudyn_forces.solve_with_forces(m, t, mode="kinematic"), mech, res.t)[1]
    agree(exu_forces, forces, rtol=1e-9)


def test_driven_slider() -> None:
    """The eight-bar driven at its slider l4: the actuator force l4.force and every reaction."""
    text = (MECH / "eightbar_dynamics.toml").read_text()
    text = text.replace('link = "l2"\npivot = "O2"\nomega = 3.0   # rad/s', 'slider = "l4"\nv = -1.0\na = 0.4')
    mech = vloop.loads(text.replace("stop = 2.35", "stop = 1.5"))
    res, forces = vloop_forces(mech)
    assert "l4.force" in forces.columns and "l2.torque" not in forces.columns
    agree(pinocchio_forces.solve_with_forces(mech, res.t)[1], forces, rtol=1e-9)
    agree(exudyn_forces.solve_with_forces(mech, res.t, mode="kinematic")[1], forces, rtol=1e-9)


def test_validators_report_partial_forces_at_a_limit() -> None:
    """A run that stops at a limit position keeps the forces of the samples solved, in every engine."""
    mech = with_masses("fourbar_nongrashof_past_limit")
    with pytest.raises(vloop.MotionError) as exc:
        pinocchio_forces.solve_with_forces(mech)
    kin, frc = exc.value.partial
    assert 0 < len(frc) == len(kin) < len(mech.times)


def test_validate_compares_forces_next_to_kinematics() -> None:
    """``vloop validate`` (the harness): every engine's Result carries its own forces, compared by group."""
    from validators import harness

    engines = ("vloop", "analytic", "pinocchio", "exudyn-kinematic")
    item = harness.validate_mechanism(MECH / "fourbar_textbook_dynamics.toml", engines)
    assert item.passed, [c.message for c in item.checks if not c.passed]
    for check in item.checks:
        groups = {e.group for e in check.comparison.errors}
        assert {"force", "moment", "acceleration"} <= groups, (check.engine, check.reference, groups)
        forces = [e for e in check.comparison.errors if e.group in ("force", "moment")]
        assert len(forces) == 1 + 4 * 3 + 3 and max(e.rel for e in forces) < 1e-11
    summary = harness.to_summary(harness.Validation([item], engines, "now", 0.0, {}))
    quantities = {q["quantity"] for c in summary["mechanisms"][0]["comparisons"] for q in c["quantities"]}
    assert {"l2.torque", "B:l3>l4.mag", "shaking.moment"} <= quantities
