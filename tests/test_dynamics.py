"""Forward dynamics (vloop.simulate) against independent references: the energy balance, a small
oscillation's period from the closed-form four-bar, a crank under a constant torque, limits, bad input.

Where each tolerance comes from:

* energy: the integrator runs at rtol = atol = 1e-12 (DOP853); its local errors in q, q̇ make the
  energy wander by ~1e-11 of its range over 10 s; the tables' midpoint error is ~1e-14 (Tables.error).
  So 1e-9 of the range holds with two orders to spare.
* period: the closed form's central differences (step 1e-4 rad) are good to ~1e-9 relative, an
  amplitude of 1e-4 rad changes the period by ~ε²/16 ≈ 1e-9 relative; the integrator (rtol 1e-12) and
  the root finding on its dense output are ~1e-10. 1e-6 leaves a wide margin.
* constant torque: θ(t) = θ₀ + ω₀t + ½(T/J)t² exactly; the integrator's 1e-12 over 2 s gives ~1e-10.
"""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

import vloop
from vloop.cli import main
from vloop.dynamics import simulate
from vloop.model import Dynamics, Spring

ROOT = Path(__file__).resolve().parents[1]

# The textbook four-bar in metres (a = 0.04, b = 0.12, c = 0.08, d = 0.1), steel bars, centres of mass at
# mid-length (the default: the mean of each link's joints), gravity along −y.
FOURBAR = """
name = "fb_m"
units = "m"
gravity = [0.0, -9.81]
[joints]
O2 = [0.0, 0.0]
A  = [0.03064177772475912, 0.02571150438746157]
B  = [0.14318998821048504, 0.06733962368753009]
O4 = [0.1, 0.0]
[links]
ground = { joints = ["O2", "O4"], ground = true }
l2 = { joints = ["O2", "A"], length = 0.04, mass = 0.0785, inertia = 1.0466666666666668e-05 }
l3 = { joints = ["A", "B"], length = 0.12, mass = 0.2355, inertia = 2.826e-4 }
l4 = { joints = ["O4", "B"], length = 0.08, mass = 0.157, inertia = 8.373333333333334e-05 }
[[drivers]]
link = "l2"
omega = 0.0
[time]
stop = 10.0
step = 0.01
"""
A_, B_, C_, D_ = 0.04, 0.12, 0.08, 0.1
MASS = (0.0785, 0.2355, 0.157)
INERTIA = (1.0466666666666668e-05, 2.826e-4, 8.373333333333334e-05)
TIGHT = {"rtol": 1e-12, "atol": 1e-12}


def fourbar(dynamics: Dynamics | None = None, text: str = FOURBAR) -> vloop.Mechanism:
    import dataclasses

    return dataclasses.replace(vloop.loads(text), dynamics=dynamics or Dynamics(**TIGHT))


def closed_form(theta: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centres of mass (3, 2) and link angles (3,) of the four-bar at crank angle θ, open branch (B above the
    line O4 → A's left side as drawn), by intersecting the circles |B − A| = b, |B − O4| = c."""
    a = np.array([A_ * math.cos(theta), A_ * math.sin(theta)])
    o4 = np.array([D_, 0.0])
    e = o4 - a
    L = math.hypot(*e)
    x = (B_**2 - C_**2 + L**2) / (2 * L)
    h = math.sqrt(B_**2 - x**2)
    u = e / L
    b = a + x * u + h * np.array([-u[1], u[0]])  # on the left of A → O4: the drawn assembly
    g = np.array([a / 2, (a + b) / 2, (o4 + b) / 2])
    ang = np.array([theta, math.atan2(*(b - a)[::-1]), math.atan2(*(b - o4)[::-1])])
    return g, ang, b


def test_closed_form_is_the_files_assembly() -> None:
    mech = vloop.loads(FOURBAR)
    _, _, b = closed_form(math.atan2(mech.joints["A"][1], mech.joints["A"][0]))
    assert np.allclose(b, mech.joints["B"], atol=1e-12)


def _energy_ok(sim, what: str) -> None:
    e = sim.energy
    span = np.ptp(e["kinetic"])
    assert span > 0
    worst = float(np.abs(e["residual"]).max())
    assert worst <= 1e-9 * span, f"{what}: residual {worst:.3g} J of a range {span:.3g} J"


def test_fourbar_swinging_under_gravity_conserves_energy() -> None:
    sim = simulate(fourbar())
    assert sim.t[-1] == pytest.approx(10.0)
    _energy_ok(sim, "four-bar")
    assert not np.any(sim.energy["work_input"])


def test_slider_crank_swinging_under_gravity_conserves_energy() -> None:
    import dataclasses

    mech = vloop.load(ROOT / "mechanisms" / "slider_crank_engine.toml")
    mech = dataclasses.replace(mech, loads=(), times=np.linspace(0.0, 10.0, 1001), dynamics=Dynamics(rate=0.0, **TIGHT))
    sim = simulate(mech)
    _energy_ok(sim, "slider-crank")


def test_damping_springs_and_a_motor_close_the_balance() -> None:
    dyn = Dynamics(
        motor=(0.4, 40.0), torque=-0.05, springs=(
            Spring("rotational", ("l4", "ground"), k=0.02, c=2e-4, joint="O4"),
            Spring("linear", ("A", "O4"), k=5.0, c=0.05, rest=0.09),
        ), **TIGHT,
    )  # fmt: skip
    sim = simulate(fourbar(dyn), np.linspace(0.0, 4.0, 401))
    _energy_ok(sim, "motor and dampers")
    assert sim.energy["work_dampers"][-1] < 0 < sim.energy["work_input"][-1]
    assert np.any(sim.energy["springs"])


def _potential(theta: float) -> float:
    g, _, _ = closed_form(theta)
    return float(sum(m * 9.81 * gy for m, gy in zip(MASS, g[:, 1], strict=True)))


def _inertia(theta: float, h: float = 1e-5) -> float:
    """J = Σ m|∂r_G/∂θ|² + I(∂φ/∂θ)² by central differences of the closed form."""
    gp, ap, _ = closed_form(theta + h)
    gm, am, _ = closed_form(theta - h)
    dg, da = (gp - gm) / (2 * h), (ap - am) / (2 * h)
    return float(
        sum(
            m * (dg[i] @ dg[i]) + inertia * da[i] ** 2 for i, (m, inertia) in enumerate(zip(MASS, INERTIA, strict=True))
        )
    )


def test_small_oscillation_period_matches_the_closed_form() -> None:
    h = 1e-4
    dv = lambda th: (_potential(th + h) - _potential(th - h)) / (2 * h)  # noqa: E731
    grid = np.linspace(0, 2 * math.pi, 721)
    slopes = np.array([dv(x) for x in grid])
    k = next(i for i in range(720) if slopes[i] < 0 <= slopes[i + 1])  # a minimum of V
    eq = brentq(dv, grid[k], grid[k + 1], xtol=1e-14)
    curvature = (_potential(eq + h) - 2 * _potential(eq) + _potential(eq - h)) / h**2
    period = 2 * math.pi * math.sqrt(_inertia(eq) / curvature)
    eps = 1e-4
    mech = fourbar(Dynamics(position=eq + eps, rate=0.0, rtol=1e-12, atol=1e-15))
    sim = simulate(mech, np.linspace(0.0, 3.2 * period, 400))
    crossings = _upward_crossings(sim, eq)
    measured = float(np.mean(np.diff(crossings)))
    assert len(crossings) >= 3
    assert measured == pytest.approx(period, rel=1e-6)


def _upward_crossings(sim, level: float) -> np.ndarray:
    """Times the input passes ``level`` upwards, located on the integrator's dense output."""
    t = np.linspace(0.0, sim.t[-1], 4001)
    q = sim.ode.sol(t)[0] - level
    out = []
    for i in np.flatnonzero((q[:-1] < 0) & (q[1:] >= 0)):
        out.append(brentq(lambda x: sim.ode.sol(x)[0] - level, t[i], t[i + 1], xtol=1e-15))
    return np.array(out)


def test_constant_torque_on_a_pure_inertia_follows_the_energy_equation() -> None:
    """Only the crank has mass (centre of mass 20 mm from O2): J = I + m·r² is constant, so
    θ = θ₀ + ω₀t + ½(T/J)t² and ½J(ω² − ω₀²) = T·(θ − θ₀)."""
    text = FOURBAR.replace("gravity = [0.0, -9.81]\n", "").replace(", mass = 0.2355, inertia = 2.826e-4", "")
    text = text.replace(", mass = 0.157, inertia = 8.373333333333334e-05", "")
    torque, w0 = 0.01, 2.0
    mech = fourbar(Dynamics(torque=torque, rate=w0, **TIGHT), text)
    t = np.linspace(0.0, 2.0, 201)
    sim = simulate(mech, t)
    J = INERTIA[0] + MASS[0] * (A_ / 2) ** 2
    th0 = math.atan2(0.02571150438746157, 0.03064177772475912)
    theta = th0 + w0 * t + 0.5 * torque / J * t**2
    assert np.allclose(sim.result["l2.theta"], theta, rtol=0, atol=1e-9 * theta.max())
    omega = np.sqrt(w0**2 + 2 * torque * (sim.result["l2.theta"] - th0) / J)
    assert np.allclose(sim.result["l2.omega"], omega, rtol=1e-9)
    assert np.allclose(sim.result["l2.torque"], torque)


def test_a_motor_line_on_a_pure_inertia_approaches_its_speed_exponentially() -> None:
    """J constant (only the crank has mass), T = T0·(1 − ω/ω0) − τ: J·ω̇ = T0 − τ − (T0/ω0)·ω, so
    ω(t) = ω_ss + (ω(0) − ω_ss)·e^(−t/τc), ω_ss = ω0·(1 − τ/T0), τc = J·ω0/T0; the last turn's mean speed is ω_ss."""
    from vloop.dynamics.cycle import cycle

    text = FOURBAR.replace("gravity = [0.0, -9.81]\n", "").replace(", mass = 0.2355, inertia = 2.826e-4", "")
    text = text.replace(", mass = 0.157, inertia = 8.373333333333334e-05", "")
    stall, speed, load = 0.01, 30.0, 0.0025
    mech = fourbar(Dynamics(motor=(stall, speed), torque=-load, rate=0.0, **TIGHT), text)
    t = np.linspace(0.0, 3.0, 301)
    sim = simulate(mech, t)
    J = INERTIA[0] + MASS[0] * (A_ / 2) ** 2
    w_ss, tau = speed * (1 - load / stall), J * speed / stall
    assert np.allclose(sim.result["l2.omega"], w_ss * (1 - np.exp(-t / tau)), rtol=0, atol=1e-9 * w_ss)
    c = cycle(sim)
    assert c.mean_speed == pytest.approx(w_ss, rel=1e-7) and c.cs < 1e-7 and c.steady


SLIDER_INPUT = """
name = "sc"
units = "cm"
gravity = [0.0, -9.81]
[joints]
O2 = [0.0, 0.0]
A = [0.0, 10.0]
B = [30.0, 0.0]
[links]
ground = { joints = ["O2"], ground = true }
crank = { joints = ["O2", "A"], mass = 1.0, inertia = 0.002 }
rod = { joints = ["A", "B"], mass = 0.5, inertia = 0.004 }
[sliders]
blk = { joint = "B", guide = "ground", axis = [1.0, 0.0], mass = 2.0 }
[[drivers]]
slider = "blk"
v = -10.0
[time]
stop = 3.0
step = 0.01
[dynamics]
rtol = 1e-12
atol = 1e-12
[[dynamics.springs]]
between = ["B", "O2"]
k = 200.0
"""


def test_a_slider_input_in_centimetres_with_a_spring_conserves_energy() -> None:
    """The piston of a slider-crank as the input (q = s, in cm in the file, metres in the equations), a
    200 N/m spring from the crank pivot to the piston, gravity: the energy stays (spring + gravity + kinetic)."""
    sim = simulate(vloop.loads(SLIDER_INPUT))
    _energy_ok(sim, "slider input")
    assert np.ptp(sim.energy["springs"]) > 0 and sim.result["blk.s"].min() > 21.6  # swings inside its limits


def test_a_slider_input_pushed_to_its_dead_centre_stops_there() -> None:
    """The same piston pushed outwards by 50 N (no spring): it stops where crank and rod are collinear,
    s = a + b = 10 + √1000 cm (by hand: A at distance 10 from O2, |AB| = √(30² + 10²)), the rows before kept and
    the energy balance closed on them (integrator at 1e-12: 1e-9 of the work is wide)."""
    with pytest.raises(vloop.MotionError) as info:
        simulate(vloop.loads(SLIDER_INPUT), torque=50.0, springs=())
    sim = info.value.partial
    t_stop, at = sim.stop
    assert abs(at - (10.0 + math.sqrt(1000.0))) < 1e-9 and "s_blk = 41.6227766 cm" in str(info.value)
    assert 0 < len(sim.t) and sim.t[-1] <= t_stop < sim.t[-1] + 0.01 and np.all(np.isfinite(sim.result["rod.theta"]))
    assert np.abs(sim.energy["residual"]).max() < 1e-9 * sim.energy["work_input"][-1]


NONGRASHOF = """
name = "ng"
units = "m"
[joints]
O2 = [0.0, 0.0]
A  = [3.0, 0.0]
B  = [3.791666666666666, 3.9208753982865727]
O4 = [6.0, 0.0]
[links]
ground = { joints = ["O2", "O4"], ground = true }
l2 = { joints = ["O2", "A"], length = 3.0, mass = 1.0, inertia = 0.75 }
l3 = { joints = ["A", "B"], length = 4.0, mass = 1.0, inertia = 1.3 }
l4 = { joints = ["O4", "B"], length = 4.5, mass = 1.0, inertia = 1.7 }
[[drivers]]
link = "l2"
[time]
stop = 5.0
step = 0.01
[dynamics]
torque = 5.0
"""


def test_a_limit_position_stops_the_motion_cleanly(tmp_path: Path) -> None:
    mech = vloop.loads(NONGRASHOF)
    with pytest.raises(vloop.MotionError) as info:
        simulate(mech)
    sim = info.value.partial
    lim = math.acos(-27.25 / 36)  # cos θ₂ = (a² + d² − (b + c)²)/(2ad): the limit, by hand
    assert "limit position" in str(info.value) and f"{lim:.6f}"[:7] in str(info.value)
    assert 0 < len(sim.t) < 501 and np.all(np.isfinite(sim.result["l3.theta"]))
    assert sim.result["l2.theta"][-1] < lim
    # the stop is the limit itself (the kinematic run's root of the dyad's discriminant), to 1e-9 rad
    t_stop, at = sim.stop
    assert abs(at - lim) < 1e-9 and abs(info.value.limit_value[0] - lim) < 1e-9
    assert f"t = {t_stop:.10g} s" in str(info.value) and f"{len(sim.t)} earlier samples kept" in str(info.value)
    # when: from rest at θ₂ = 0 under T = 5 N·m, ½·J(θ)·ω² = T·θ, so t = ∫ dθ/ω = ∫ √(J/(2Tθ)) dθ up to the limit,
    # J from the closed-form four-bar (validators.analytic), the ends' 1/√ taken out by θ = lim·sin²φ: quad to
    # ~1e-13; the integrator (rtol 1e-10 by default) and the tables (1e-9 at worst, near the limit) give ~1e-10 s
    assert abs(t_stop - _time_to_the_limit(mech, lim, 5.0)) < 1e-8
    assert sim.t[-1] <= t_stop < sim.t[-1] + 0.01  # every row before the stop kept
    # the energy balance holds on the rows up to the limit (the last ones on the tables in u): 1e-8 of the work
    assert np.abs(sim.energy["residual"]).max() < 1e-8 * sim.energy["work_input"][-1]
    (tmp_path / "ng.toml").write_text(NONGRASHOF)
    out = _cli(tmp_path, "simulate", "ng.toml", "--out", "o")
    assert out.returncode == 2 and "limit position" in out.stderr and "Traceback" not in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
    rows = (tmp_path / "o" / "results.csv").read_text().splitlines()
    assert len(rows) == len(sim.t) + 1  # the header, the rows (as vloop run writes them)


def _time_to_the_limit(mech: vloop.Mechanism, lim: float, torque: float) -> float:
    """Time [s] from rest at θ₂ = 0 to the limit under a constant torque, by the energy equation and the
    closed-form four-bar's velocities at unit input rate (centres of mass at mid-link, the file's masses)."""
    from validators.analytic import fourbar

    d = mech.drivers[0]
    unit = dataclasses.replace(mech, drivers=(dataclasses.replace(d, v0=1.0, a0=0.0, profile=None),))

    def inertia(q: float) -> float:
        r = fourbar.solve(unit, np.array([q]))
        total = 0.0
        for link, (p, s) in (("l2", ("O2", "A")), ("l3", ("A", "B")), ("l4", ("O4", "B"))):
            vx, vy = 0.5 * (r[f"{p}.vx"] + r[f"{s}.vx"]), 0.5 * (r[f"{p}.vy"] + r[f"{s}.vy"])
            mp = mech.masses[link]
            total += float((mp.mass * (vx**2 + vy**2) + mp.inertia * r[f"{link}.omega"] ** 2)[0])
        return total

    def integrand(phi: float) -> float:  # dθ/√(θ·(lim − θ)) = 2 dφ
        q = lim * math.sin(phi) ** 2
        return 2.0 * math.sqrt(inertia(q) * (lim - q) / (2.0 * torque))

    return quad(integrand, 0.0, 0.5 * math.pi, epsabs=1e-13, epsrel=1e-13, limit=200)[0]


def _cli(folder: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vloop.cli", *args], cwd=folder, capture_output=True, text=True)


@pytest.mark.parametrize(
    ("section", "says"),
    [
        ('method = "Euler"', "method must be one of"),
        ("flywheel = -1.0", "'flywheel' must not be negative"),
        ("motor = { stall = 1.0, no_load_speed = 0.0 }", "'no_load_speed' must not be zero"),
        ("motor = 3.0", "dynamics.motor"),
        ("rtol = 2.0", "rtol must be between 0 and 1"),
        ("speed = 1.0", "unknown key 'speed'"),
        ("[[dynamics.springs]]\njoint = 'Q'\nk = 1.0", "'joint' must name a pin"),
        ("[[dynamics.springs]]\nbetween = ['A', 'A']\nk = 1.0", "'between' must name two different"),
        ("[[dynamics.springs]]\njoint = 'O4'\nbetween = ['A', 'B']", "give joint = J"),
        ("torque = { t = [0.0, 1.0] }", "profile needs columns 't' and 'torque'"),
        ("[[dynamics.springs]]\nbetween = [[1], 2]\nk = 1.0", "'between' must name two different"),
        ("stop = 2.0", "give both 'stop' and 'step'"),
    ],
)
def test_bad_dynamics_input_is_one_line_and_exit_2(tmp_path: Path, capsys, section: str, says: str) -> None:
    text = NONGRASHOF.replace("torque = 5.0", section)
    (tmp_path / "bad.toml").write_text(text)
    assert main(["simulate", str(tmp_path / "bad.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert says in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "o").exists()


def test_a_mechanism_without_inertia_is_refused_with_one_line(tmp_path: Path, capsys) -> None:
    text = NONGRASHOF
    for body in (", mass = 1.0, inertia = 0.75", ", mass = 1.0, inertia = 1.3", ", mass = 1.0, inertia = 1.7"):
        text = text.replace(body, "")
    (tmp_path / "light.toml").write_text(text)
    assert main(["simulate", str(tmp_path / "light.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "has no inertia" in err and len(err.strip().splitlines()) == 1


def test_two_inputs_with_what_this_version_does_not_take_get_one_line(tmp_path: Path, capsys) -> None:
    text = (ROOT / "mechanisms" / "fivebar_two_cranks.toml").read_text() + "\n[dynamics]\ntorque = 1.0\n"
    (tmp_path / "five.toml").write_text(text)
    assert main(["simulate", str(tmp_path / "five.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "two inputs takes gravity and the masses only" in err and len(err.strip().splitlines()) == 1
    (tmp_path / "light.toml").write_text(text.replace("torque = 1.0", ""))  # no masses: no equation of motion
    assert main(["simulate", str(tmp_path / "light.toml"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "no inertia" in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_the_section_reads_back_from_its_toml() -> None:
    mech = vloop.load(ROOT / "mechanisms" / "fourbar_textbook_dynamics.toml")
    again = vloop.loads(vloop.dumps(mech))
    assert again.dynamics == mech.dynamics and mech.dynamics is not None and mech.dynamics.motor is not None


def test_an_implicit_method_follows_a_stiff_spring() -> None:
    """A stiff rotational spring at the rocker (k = 50 N·m/rad: ~200 rad/s against the swing's few rad/s):
    Radau (implicit) and DOP853 (explicit) give the same motion within their tolerances (1e-10 relative each,
    so 1e-7 of the angle's range over 0.3 s leaves room for the error growth of an oscillation)."""
    spring = (Spring("rotational", ("l4", "ground"), k=50.0, c=0.0, joint="O4"),)
    t = np.linspace(0.0, 0.3, 31)
    explicit = simulate(fourbar(Dynamics(springs=spring, rtol=1e-10, atol=1e-12)), t)
    implicit = simulate(fourbar(Dynamics(springs=spring, method="Radau", rtol=1e-10, atol=1e-12)), t)
    th = explicit.result["l2.theta"]
    assert np.ptp(th) > 1e-3
    assert np.allclose(implicit.result["l2.theta"], th, rtol=0, atol=1e-7 * np.ptp(th))
    _energy_ok(implicit, "Radau")


def test_simulate_writes_what_run_writes_plus_torque_and_energy(tmp_path: Path) -> None:
    text = (ROOT / "mechanisms" / "fourbar_textbook_dynamics.toml").read_text().replace("stop = 4.0 ", "stop = 0.3 ")
    (tmp_path / "fb.toml").write_text(text)
    assert main(["simulate", str(tmp_path / "fb.toml"), "--out", str(tmp_path / "o"), "--plot", "--html"]) == 0
    assert main(["run", str(tmp_path / "fb.toml"), "--out", str(tmp_path / "r")]) == 0
    sim = vloop.Result.read_csv(tmp_path / "o" / "results.csv")
    run = vloop.Result.read_csv(tmp_path / "r" / "results.csv")
    assert list(sim.columns) == [*run.columns, "l2.torque"] and len(sim) == 61
    energy = (tmp_path / "o" / "energy.csv").read_text().splitlines()[0].split(",")
    assert energy == ["t", "kinetic", "gravity", "springs", "work_input", "work_loads", "work_dampers", "residual"]
    for name in ("health.csv", "energy.png", "links.png", "fourbar_textbook_dynamics.html"):
        assert (tmp_path / "o" / name).is_file(), name


# ---------------------------------------------------------------- two inputs
#
# The catalog's five-bar (two cranks, one RRR dyad on their pins; it assembles whatever the inputs do) with
# masses on its four links and gravity, released from rest at the drawing.
FIVEBAR_MASSES = {"l2": (1.0, 0.4), "l3": (2.0, 6.0), "l4": (1.5, 3.2), "l5": (1.0, 0.4)}
FIVEBAR_JOINTS = {"l2": ("O2", "A"), "l3": ("A", "C"), "l4": ("D", "C"), "l5": ("O5", "D")}


def _fivebar() -> vloop.Mechanism:
    import tomllib

    raw = tomllib.loads((ROOT / "mechanisms" / "fivebar_two_cranks.toml").read_text())
    raw["gravity"] = [0.0, -9.81]
    for link, (m, inertia) in FIVEBAR_MASSES.items():
        raw["links"][link].update(mass=m, inertia=inertia)
    for d in raw["drivers"]:
        d.update(omega=0.0, alpha=0.0)
    return vloop.from_dict(raw)


@pytest.mark.parametrize("rates", [(0.0, 0.0), (5.0, -3.0)])
def test_a_fivebar_starts_as_its_closed_form_says(rates: tuple[float, float]) -> None:
    """q̈(0) = J⁻¹·(Q − h) with J_ij = Σ m·∂r_G/∂qᵢ·∂r_G/∂qⱼ + I·∂φ/∂qᵢ·∂φ/∂qⱼ, Q_i = Σ m·g·∂r_G/∂qᵢ and
    h_i = Σ m·∂r_G/∂qᵢ·a₀ + I·∂φ/∂qᵢ·α₀ (a₀, α₀: the accelerations at the rates q̇ with q̈ = 0; h = 0 from rest):
    every coefficient from the closed-form five-bar (validators.analytic) at the drawing, the centres of mass at
    mid-link. Round-off of a 2×2 solve: 1e-9 relative is wide."""
    from validators.analytic import fivebar

    mech = _fivebar()
    mech = dataclasses.replace(
        mech, drivers=tuple(dataclasses.replace(d, v0=w) for d, w in zip(mech.drivers, rates, strict=True))
    )
    runs = []
    for unit in ((1.0, 0.0), (0.0, 1.0), rates):
        drivers = tuple(dataclasses.replace(d, v0=w, a0=0.0) for d, w in zip(mech.drivers, unit, strict=True))
        runs.append(fivebar.solve(dataclasses.replace(mech, drivers=drivers), np.zeros(1)))
    J, Q, h = np.zeros((2, 2)), np.zeros(2), np.zeros(2)
    for link, (m, inertia) in FIVEBAR_MASSES.items():
        p, s = FIVEBAR_JOINTS[link]
        v = np.array([[0.5 * (r[f"{p}.v{c}"][0] + r[f"{s}.v{c}"][0]) for c in "xy"] for r in runs[:2]])
        w = np.array([r[f"{link}.omega"][0] for r in runs[:2]])
        a0 = np.array([0.5 * (runs[2][f"{p}.a{c}"][0] + runs[2][f"{s}.a{c}"][0]) for c in "xy"])
        J += m * v @ v.T + inertia * np.outer(w, w)
        Q += m * v @ np.array([0.0, -9.81])
        h += m * v @ a0 + inertia * w * runs[2][f"{link}.alpha"][0]
    expected = np.linalg.solve(J, Q - h)
    sim = simulate(mech, np.array([0.0, 0.01]), **TIGHT)
    got = np.array([sim.result["l2.alpha"][0], sim.result["l5.alpha"][0]])
    assert np.abs(got - expected).max() <= 1e-9 * np.abs(expected).max()
    assert np.abs(expected).min() > 0.1  # both inputs do accelerate: the test sees the coupling
    assert (np.abs(h).max() > 1.0) == any(rates)  # with rates, the Christoffel terms are in play
    with pytest.raises(vloop.MechanismError, match="two inputs takes gravity and the masses only"):
        simulate(mech, np.array([0.0, 0.01]), torque=1.0)


@pytest.mark.slow
def test_a_fivebar_swinging_under_gravity_conserves_energy() -> None:
    """3 s of the five-bar falling and swinging from rest: kinetic + gravity constant to 1e-9 of its range
    (DOP853 at 1e-12; the loop solve at every call is exact to round-off)."""
    sim = simulate(_fivebar(), np.linspace(0.0, 3.0, 61), **TIGHT)
    e = sim.energy
    assert np.ptp(e["kinetic"]) > 10.0  # it does swing
    assert np.abs(e["residual"]).max() <= 1e-9 * np.ptp(e["kinetic"])
