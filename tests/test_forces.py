"""Kinetostatics (vloop.forces): every number against an independent reference.

* Closed forms derived by hand (validators/analytic/forces.py: slider-crank and four-bar) match vloop's
  driver torque, pin forces, slider normal force and moment to 1e-9 of each quantity's peak
  (measured ≤ 4e-14).
* The power balance on every catalog file with masses (and a driven-slider variant): Σ τ·ω + f·ṡ =
  dT/dt − P_gravity − P_loads at every sample, with T, dT/dt = Σ m·v_G·a_G + I·ω·α, the gravity and
  load powers all computed here from the P/V/A results alone, to 1e-9 of the peak input power
  (measured ≤ 2e-15).
* Momentum balance: the shaking force equals Σ m·g + Σ loads − Σ m·a_G and the shaking moment the
  rate of angular momentum balance about the origin, from the kinematics alone (1e-9 of peak).
* A published worked example: D. B. Marghitu, *Mechanisms and Robots Analysis with MATLAB*
  (Springer, 2009), §4 "Dynamic Force Analysis", the R-RRT slider-crank (AB = BC = 1 m,
  φ = π/4, n = 30/π rpm, m = 1 kg each, g = 10 m/s², 100 N on the slider against its motion):
  printed F12 = −(1/4)(400 + 7√2) i + (5/4)(84 + √2) j N (Eqs. 4.51–4.52, p. 144), reproduced to
  its digits; the other reactions and the crank moment are derived by hand below.
* A redundant (over-constrained) linkage: the reactions the equations leave free are listed and get
  no number; the driver torque (from the power balance) and the shaking force still do.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import vloop
from validators.analytic import forces as analytic_forces
from vloop.compare import assert_histories_close
from vloop.forces import ForceError, compile_forces, load_values, solve_forces
from vloop.mechanism import Driver, Link, MassProperties, Mechanism, length_factor
from vloop.result import Result

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
WITH_MASSES = sorted(p.stem for p in MECH.glob("*.toml") if vloop.load(p).masses)
S2 = math.sqrt(2.0)


def load(stem: str) -> vloop.Mechanism:
    return vloop.load(MECH / f"{stem}.toml")


def test_the_catalog_has_the_dynamics_files() -> None:
    assert {"slider_crank_engine", "eightbar_dynamics", "fourbar_textbook_dynamics", "sixbar_watt2_dynamics"} <= set(
        WITH_MASSES
    )


# ---------------------------------------------------------------- closed forms


@pytest.mark.parametrize("stem", ["slider_crank_engine", "fourbar_textbook_dynamics"])
def test_matches_the_hand_derived_closed_form(stem: str) -> None:
    mech = load(stem)
    res = vloop.solve(mech)
    forces = solve_forces(mech, res)
    ref = analytic_forces.solve_forces(mech, res.t)  # its own closed-form kinematics
    assert set(ref.columns) == set(forces.columns)
    cmp = assert_histories_close(forces.as_result(), ref.as_result(), rtol=1e-9, min_columns=len(forces.columns))
    assert {e.group for e in cmp.errors} == {"force", "moment"}
    assert max(e.rel for e in cmp.errors) < 1e-12


# ---------------------------------------------------------------- power and momentum balance


def body_kinematics(mech: Mechanism, res: Result, body: str) -> dict[str, np.ndarray]:
    """G, v_G, a_G [m, m/s, m/s²] of a body from its frame origin's columns and its θ, ω, α (here, by hand)."""
    f = length_factor(mech.units)
    b = mech.bodies()[body]
    mp = mech.masses[body]
    c, s = math.cos(b.theta0), math.sin(b.theta0)
    dx, dy = mp.com[0] - b.origin[0], mp.com[1] - b.origin[1]
    local = (c * dx + s * dy, -s * dx + c * dy)
    o = b.joints[0]
    th, om, al = res[f"{body}.theta"], res[f"{body}.omega"], res[f"{body}.alpha"]
    rx = (np.cos(th) * local[0] - np.sin(th) * local[1]) * f
    ry = (np.sin(th) * local[0] + np.cos(th) * local[1]) * f
    return {
        "g": np.column_stack([res[f"{o}.x"] * f + rx, res[f"{o}.y"] * f + ry]),
        "v": np.column_stack([res[f"{o}.vx"] * f - om * ry, res[f"{o}.vy"] * f + om * rx]),
        "a": np.column_stack(
            [res[f"{o}.ax"] * f - al * ry - om * om * rx, res[f"{o}.ay"] * f + al * rx - om * om * ry]
        ),
    }


def powers(mech: Mechanism, res: Result, forces) -> tuple[np.ndarray, np.ndarray]:
    """(Σ driver power, dT/dt − gravity power − load power) [W] at every sample."""
    f = length_factor(mech.units)
    g = np.asarray(mech.gravity or (0.0, 0.0))
    rhs = np.zeros(len(res.t))
    for body, mp in mech.masses.items():
        k = body_kinematics(mech, res, body)
        rhs += mp.mass * np.sum(k["v"] * k["a"], axis=1) + mp.inertia * res[f"{body}.omega"] * res[f"{body}.alpha"]
        rhs -= mp.mass * k["v"] @ g
    for ld in mech.loads:
        v = load_values(ld, res.t)
        if ld.kind == "torque":
            rhs -= v * res[f"{ld.body}.omega"]
        else:
            rhs -= (v[:, 0] * res[f"{ld.point}.vx"] + v[:, 1] * res[f"{ld.point}.vy"]) * f
    power = np.zeros(len(res.t))
    for d in mech.drivers:
        if d.kind == "crank":
            power += forces[f"{d.target}.torque"] * res[f"{d.target}.omega"]
        else:
            power += forces[f"{d.target}.force"] * res[f"{d.target}.v"] * f
    return power, rhs


def slider_driven_eightbar() -> Mechanism:
    text = (MECH / "eightbar_dynamics.toml").read_text()
    text = text.replace('link = "l2"\npivot = "O2"\nomega = 3.0   # rad/s', 'slider = "l4"\nv = -1.0\na = 0.4')
    return vloop.loads(text.replace("stop = 2.35", "stop = 1.5"), source="eightbar_slider_driven.toml")


def mechanisms_with_masses() -> list[tuple[str, Mechanism]]:
    return [(s, load(s)) for s in WITH_MASSES] + [("eightbar_slider_driven", slider_driven_eightbar())]


@pytest.mark.parametrize("name,mech", mechanisms_with_masses(), ids=lambda x: x if isinstance(x, str) else "")
def test_power_balance(name: str, mech: Mechanism) -> None:
    res = vloop.solve(mech)
    forces = solve_forces(mech, res)
    power, rhs = powers(mech, res, forces)
    peak = np.max(np.abs(power))
    assert peak > 0
    assert np.max(np.abs(power - rhs)) <= 1e-9 * peak, (
        f"{name}: power balance off by {np.max(np.abs(power - rhs)) / peak:.2e} of peak"
    )


def test_default_centre_of_mass_is_the_mean_of_the_joints_as_assembled() -> None:
    """The paper's eight-bar with masses, its C and D typed with the paper's rounded k = 4.6715 (exact
    4.671455876…; the rods' stated length 6.15 places them on assembly) and no ``com``: each body's centre of
    mass is the mean of its joints as solved, so here G, v_G, a_G are the means of the joints' columns of the
    Result (a block's: its joint) — no body frame, no ``com`` read from vloop. The power balance Σ τ·ω =
    dT/dt − P_gravity − P_loads then holds to round-off: measured 4.5e-16 of the peak power (3.9e-6 when the
    default was the mean of the typed coordinates)."""
    text = (MECH / "eightbar_dynamics.toml").read_text().replace("4.671455875848556", "4.6715")
    mech = vloop.loads(text, source="eightbar_rounded.toml")
    assert "com" not in text  # every centre of mass is the default
    res = vloop.solve(mech)
    assert abs(res["C.y"][0] - math.sqrt(6.15**2 - 4.0**2)) <= 1e-12  # assembled, not typed
    forces = solve_forces(mech, res)
    g = np.asarray(mech.gravity)
    rhs = np.zeros(len(res.t))
    for body, mp in mech.masses.items():
        joints = mech.links[body].joints if body in mech.links else (mech.sliders[body].joint,)
        v = np.mean([np.column_stack([res[f"{j}.vx"], res[f"{j}.vy"]]) for j in joints], axis=0)
        a = np.mean([np.column_stack([res[f"{j}.ax"], res[f"{j}.ay"]]) for j in joints], axis=0)
        rhs += mp.mass * np.sum(v * a, axis=1) + mp.inertia * res[f"{body}.omega"] * res[f"{body}.alpha"]
        rhs -= mp.mass * v @ g
    (payload,) = mech.loads  # 500 N down at C
    rhs -= load_values(payload, res.t)[:, 1] * res["C.vy"]
    power = forces["l2.torque"] * res["l2.omega"]
    assert np.max(np.abs(power - rhs)) <= 1e-12 * np.max(np.abs(power))


@pytest.mark.parametrize("name,mech", mechanisms_with_masses(), ids=lambda x: x if isinstance(x, str) else "")
def test_shaking_force_and_moment_from_momentum(name: str, mech: Mechanism) -> None:
    """What the ground receives = weights + loads − rate of momentum (force); about the origin for the moment."""
    f = length_factor(mech.units)
    res = vloop.solve(mech)
    forces = solve_forces(mech, res)
    g = np.asarray(mech.gravity or (0.0, 0.0))
    force = np.zeros((len(res.t), 2))
    moment = np.zeros(len(res.t))
    for body, mp in mech.masses.items():
        k = body_kinematics(mech, res, body)
        net = mp.mass * (g - k["a"])  # weight minus m·a_G: what the rest of the world must not supply
        force += net
        moment += k["g"][:, 0] * net[:, 1] - k["g"][:, 1] * net[:, 0] - mp.inertia * res[f"{body}.alpha"]
    for ld in mech.loads:
        v = load_values(ld, res.t)
        if ld.kind == "torque":
            moment += v
            continue
        p = np.column_stack([res[f"{ld.point}.x"], res[f"{ld.point}.y"]]) * f
        force += v
        moment += p[:, 0] * v[:, 1] - p[:, 1] * v[:, 0]
    sh = forces.shaking
    for got, want in ((sh.fx, force[:, 0]), (sh.fy, force[:, 1]), (sh.moment, moment)):
        assert np.max(np.abs(got - want)) <= 1e-9 * max(np.max(np.abs(want)), 1e-300)


# ---------------------------------------------------------------- the published example


def marghitu() -> Mechanism:
    """Marghitu's R-RRT slider-crank at φ = π/4 (one sample): crank l1 = AB, rod l2 = BC, slider l3 at C."""
    return vloop.from_dict(
        {
            "name": "marghitu_rrrt",
            "units": "m",
            "gravity": [0.0, -10.0],
            "joints": {"A": [0.0, 0.0], "B": [S2 / 2, S2 / 2], "C": [S2, 0.0]},
            "links": {
                "l0": {"joints": ["A"], "ground": True},
                # IC = m (L² + h²)/12 with h = 0.01 m: 0.0833417 kg m² as printed (α = 0 here anyway)
                "l1": {"joints": ["A", "B"], "mass": 1.0, "inertia": 0.0833417, "com": [S2 / 4, S2 / 4]},
                "l2": {"joints": ["B", "C"], "mass": 1.0, "inertia": 0.0833417, "com": [3 * S2 / 4, S2 / 4]},
            },
            "sliders": {"l3": {"joint": "C", "guide": "l0", "axis": [1.0, 0.0], "mass": 1.0, "inertia": 1.66667e-5}},
            # v_C = −√2 m/s, so the 100 N driven force opposed to the motion points along +x
            "loads": [{"point": "C", "force": [100.0, 0.0]}],
            "drivers": [{"link": "l1", "pivot": "A", "omega": 1.0}],  # n = 30/π rpm: ω = 1 rad/s, constant
            "time": {"times": [0.0]},
        }
    )


def test_marghitu_slider_crank_printed_joint_force() -> None:
    mech = marghitu()
    res = vloop.solve(mech)
    # the printed kinematics of the example: v_C = −√2 m/s, a_C = −√2 m/s², ω2 = −1 rad/s, α1 = α2 = 0
    assert res["C.vx"][0] == pytest.approx(-S2, rel=1e-12) and res["C.ax"][0] == pytest.approx(-S2, rel=1e-12)
    assert res["l2.omega"][0] == pytest.approx(-1.0, rel=1e-12) and abs(res["l2.alpha"][0]) < 1e-12
    forces = solve_forces(mech, res)
    # printed: F12x = −(1/4)(400 + 7√2) N, F12y = (5/4)(84 + √2) N  (force of crank 1 on rod 2 at B)
    assert forces["B:l1>l2.fx"][0] == pytest.approx(-(400 + 7 * S2) / 4, rel=1e-12)
    assert forces["B:l1>l2.fy"][0] == pytest.approx(5 * (84 + S2) / 4, rel=1e-12)
    assert f"{forces['B:l1>l2.fx'][0]:.3f}, {forces['B:l1>l2.fy'][0]:.3f}" == "-102.475, 106.768"


def test_marghitu_slider_crank_other_reactions_by_hand() -> None:
    """The rest of the example, derived here by hand from the printed data (Newton–Euler per link).

    Rod 2: F32 = m2·a_C2 − m2·g − F12 = (100 + √2, −95 − 3√2/2), so the rod pushes the slider with
    F23 = −F32 = (−100 − √2, 95 + 3√2/2). Slider 3 (vertical guide force N, a_C = (−√2, 0)):
    y: 95 + 3√2/2 + N − 10 = 0 ⇒ N = −85 − 3√2/2; x: −100 − √2 + 100 = −√2 = m3·a_Cx (a check).
    Crank 1: F01 = m1·a_C1 − m1·g + F12 = (−100 − 2√2, 115 + √2); moments about A (a_C1 ∥ AC1, α1 = 0):
    M = −AB × (−F12) − AC1 × m1·g = (√2/2)(F12y − F12x) + 5√2/2 = 3 + 105√2 N·m.
    """
    forces = solve_forces(mech := marghitu(), vloop.solve(mech))
    expected = {
        "l1.torque": 3 + 105 * S2,
        "A:l0>l1.fx": -100 - 2 * S2,
        "A:l0>l1.fy": 115 + S2,
        "C:l2>l3.fx": -100 - S2,
        "C:l2>l3.fy": 95 + 1.5 * S2,
        "l3.normal": -85 - 1.5 * S2,
        "shaking.fx": 100 + 2 * S2,
        "shaking.fy": -30 + S2 / 2,
    }
    for col, value in expected.items():
        assert forces[col][0] == pytest.approx(value, rel=1e-12), col
    assert forces["l3.moment"][0] == 0.0  # every force on the slider passes through its centre of mass C
    assert f"{forces['l1.torque'][0]:.3f}" == "151.492"


# ---------------------------------------------------------------- redundant constraints


def double_parallelogram() -> tuple[Mechanism, Result]:
    """Three parallel cranks (l2, l4, l5) under one translating coupler: Gruebler M = 0, yet it moves.

    The loader refuses it (mobility), so the Mechanism and its exact kinematics are built here:
    θ(t) = π/2 + ω t + α t²/2 for every crank, the coupler l3 keeps θ = 0.
    """
    joints = {"O2": (0.0, 0.0), "A": (0.0, 1.0), "O4": (2.0, 0.0), "B": (2.0, 1.0), "O6": (1.0, 0.0), "C": (1.0, 1.0)}
    links = {
        "ground": Link("ground", ("O2", "O4", "O6"), True),
        "l2": Link("l2", ("O2", "A")),
        "l3": Link("l3", ("A", "C", "B")),
        "l4": Link("l4", ("O4", "B")),
        "l5": Link("l5", ("O6", "C")),
    }
    t = np.linspace(0.0, 2.0, 41)
    om0, al0 = 2.0, 0.5
    masses = {
        "l2": MassProperties(2.0, 0.2, (0.0, 0.5)),
        "l3": MassProperties(4.0, 1.5, (1.0, 1.1)),
        "l4": MassProperties(2.0, 0.2, (2.0, 0.5)),
        "l5": MassProperties(1.0, 0.1, (1.0, 0.5)),
    }
    mech = Mechanism(
        "double_parallelogram", joints, links, {}, {}, (Driver("crank", "l2", math.pi / 2, om0, al0, "O2"),), t,
        masses=masses, gravity=(0.0, -9.81),
    )  # fmt: skip
    th, om, al = math.pi / 2 + om0 * t + al0 * t * t / 2, om0 + al0 * t, np.full_like(t, al0)
    c, s = np.cos(th), np.sin(th)
    z = np.zeros_like(t)
    crank = (c, s, -om * s, om * c, -al * s - om * om * c, al * c - om * om * s)
    points = {
        "O2": (z, z, z, z, z, z),
        "O4": (z + 2, z, z, z, z, z),
        "O6": (z + 1, z, z, z, z, z),
        "A": crank,
        "B": (crank[0] + 2, *crank[1:]),
        "C": (crank[0] + 1, *crank[1:]),
    }
    links_k = {"l2": (th, om, al), "l3": (z, z, z), "l4": (th, om, al), "l5": (th, om, al)}
    return mech, Result.from_arrays(mech.name, "exact", t, links=links_k, points=points)


def test_redundant_reactions_are_reported_indeterminate() -> None:
    mech, res = double_parallelogram()
    assert mech.gruebler()[2] == 0
    forces = solve_forces(mech, res)
    pins = {"O2:ground>l2", "A:l2>l3", "O4:ground>l4", "B:l3>l4", "O6:ground>l5", "C:l3>l5"}
    assert set(forces.indeterminate) == pins  # a self-stress runs through all three cranks
    assert "indeterminate" in forces.message and "rank 12 for 13 unknowns" in forces.message
    assert not any(c.startswith(tuple(pins)) for c in forces.columns)  # no number for them
    with pytest.raises(KeyError, match="indeterminate"):
        forces.pin("A")
    # what the equations do fix: the torque (power balance) and what the ground receives (momentum)
    power, rhs = powers(mech, res, forces)
    assert np.max(np.abs(power - rhs)) <= 1e-9 * np.max(np.abs(power))
    weight = sum(mp.mass for mp in mech.masses.values()) * 9.81
    net_fy = -weight - sum(mp.mass * body_kinematics(mech, res, b)["a"][:, 1] for b, mp in mech.masses.items())
    assert np.max(np.abs(forces.shaking.fy - net_fy)) <= 1e-9 * weight


def test_block_order_and_least_squares_agree() -> None:
    """The batched block solve and the least-squares path (redundant mechanisms) give the same forces."""
    mech = load("eightbar_dynamics")
    res = vloop.solve(mech)
    model = compile_forces(mech)
    assert max(len(rows) for rows, _ in model.blocks) <= 2  # the eight-bar splits into 1×1 and 2×2 blocks
    fast = solve_forces(mech, res, model=model)
    slow = solve_forces(mech, res, model=dataclasses.replace(model, blocks=None))
    assert not slow.indeterminate and set(slow.columns) == set(fast.columns)
    assert_histories_close(fast.as_result(), slow.as_result(), rtol=1e-10)


# ---------------------------------------------------------------- the result object


def test_force_result_access_and_export(tmp_path: Path) -> None:
    mech = load("eightbar_dynamics")
    forces = vloop.solve_forces(mech, vloop.solve(mech))
    assert len(forces) == len(mech.times) and forces["t"] is forces.t
    assert np.array_equal(forces.driver("l2"), forces["l2.torque"])
    b = forces.pin("B", on="l7")
    assert np.allclose(b.mag, np.hypot(b.fx, b.fy))
    assert forces.slider("l6").normal is forces["l6.normal"]
    assert forces.shaking.moment is forces["shaking.moment"]
    arrows = forces.arrows
    assert ("B", "B:l3>l7.fx", "B:l3>l7.fy", "l3→l7 at B") in arrows and len(arrows) == 7
    path = forces.to_csv(tmp_path / "forces.csv")
    header = path.read_text().splitlines()[0].split(",")
    assert header[:2] == ["t", "l2.torque"] and "shaking.moment" in header
    back = np.loadtxt(path, delimiter=",", skiprows=1)
    assert np.array_equal(back[:, 1], forces["l2.torque"])  # %.17g: exact round trip
    assert list(tmp_path.iterdir()) == [path]  # atomic: no temporary file left behind
    df = forces.to_dataframe()
    assert list(df.columns) == header


def test_massless_mechanism_has_zero_forces_and_no_masses_means_no_forces() -> None:
    mech = load("eightbar")
    assert not mech.masses and not vloop.forces.has_forces(mech)
    forces = solve_forces(mech, vloop.solve(mech))
    assert all(np.all(v == 0.0) for v in forces.columns.values())


def test_overflowing_masses_raise_naming_the_quantity_and_sample() -> None:
    text = (MECH / "eightbar_dynamics.toml").read_text().replace("mass = 30.0", "mass = 1e308")
    mech = vloop.loads(text)
    with pytest.raises(ForceError, match=r"is not finite at t = .* \(sample \d+\)"):
        solve_forces(mech, vloop.solve(mech))


def test_load_profile_must_cover_the_samples() -> None:
    mech = load("slider_crank_engine")
    res = vloop.solve(mech, times=np.linspace(0.0, 0.05, 11))
    with pytest.raises(ForceError, match=r"loads\[0\].*outside the load profile's range"):
        solve_forces(mech, res)


def test_engine_gas_force_follows_its_documented_formula() -> None:
    """The CSV's rows are the pressure model written in the file's header (spot checks)."""
    mech = load("slider_crank_engine")
    prof = mech.loads[0].profile
    r, rod, bore = 0.043, 0.145, 0.086
    area = math.pi * bore**2 / 4
    vs, vc = 2 * r * area, 2 * r * area / 9

    def pressure(deg: float) -> float:
        phi = math.radians(deg)
        v = vc + area * (r + rod - r * math.cos(phi) - math.sqrt(rod * rod - (r * math.sin(phi)) ** 2))
        psi = (deg + 180.0) % 720.0 - 180.0
        pm = ((vc + vs) / v) ** 1.32
        if deg <= 180 or deg >= 540:
            return pm * (1 + 1.9 * math.exp(-(((psi - 12) / 22) ** 2)))
        return 1.10 if deg <= 360 else 0.95

    for deg in (0, 6, 90, 200, 400, 600, 719):
        assert prof.t[deg] == pytest.approx(math.radians(deg) / (100 * math.pi), rel=1e-12, abs=1e-15)
        assert prof.values[deg, 0] == pytest.approx(-(pressure(deg) - 1.0) * 1e5 * area, rel=1e-12)
    assert np.max(-prof.values[:, 0]) == pytest.approx(31597.8, rel=1e-5)  # 55.4 bar at 6° after TDC
