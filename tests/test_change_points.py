"""Change points: where a linkage's two assembly branches cross (Grashof equality), vloop continues on
the branch whose velocities stay continuous, reports where, and lets the file pick the other branch.

Every reference here is derived by hand from the geometry, not from vloop's loop equations:

* parallelogram (ground 4, crank = rocker = 2, coupler 4): on its parallelogram branch the rocker
  stays parallel to the crank and the coupler to the ground: θ4 = θ2, θ3 = 0, B = A + 4; the branches
  cross where all four pins are collinear, θ2 = kπ. The anti-parallelogram branch has B mirrored in
  the line A–O4 (the other intersection of the two circles).
* isosceles slider-crank (crank = rod = 1, no offset): s = 2·cos θ2 on the branch through the crank
  pivot; the other branch keeps B at the pivot. They cross at θ2 = π/2.
* kite (crank = coupler = a, rocker = ground = d): both circles (centre A radius a, centre O4 radius d)
  pass through O2, so B is the mirror image of O2 in the line A–O4; the branches (B and B ≡ O2) cross
  where A is on the ground line, θ2 = 0 and π.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import vloop
from vloop.cli import main
from vloop.compare import assert_histories_close

PARALLELOGRAM = """
name = "parallelogram"
[joints]
O2 = [0.0, 0.0]
O4 = [4.0, 0.0]
A = [0.0, 2.0]
B = [4.0, 2.0]
[links]
ground = {{ joints = ["O2", "O4"], ground = true }}
crank = {{ joints = ["O2", "A"] }}
coupler = {{ joints = ["A", "B"] }}
rocker = {{ joints = ["O4", "B"] }}
[[drivers]]
link = "crank"
omega = 2.0
alpha = {alpha}
[time]
start = 0.0
stop = {stop}
step = {step}
{solver}
"""


def parallelogram(alpha: float = 0.5, step: float = 0.01, solver: str = "") -> vloop.Mechanism:
    # 1.5 turns of the crank from θ2 = π/2: θ2(T) = π/2 + 2T + αT²/2 = π/2 + 3π
    stop = (-2 + math.sqrt(4 + 2 * alpha * 3 * math.pi)) / alpha if alpha else 1.5 * math.pi
    return vloop.loads(PARALLELOGRAM.format(alpha=alpha, stop=stop, step=step, solver=solver))


def crank_motion(mech: vloop.Mechanism) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    d = mech.drivers[0]
    t = mech.times
    return d.x0 + d.v0 * t + 0.5 * d.a0 * t * t, d.v0 + d.a0 * t, np.full_like(t, d.a0)


def test_parallelogram_through_one_and_a_half_turns_stays_a_parallelogram():
    mech = parallelogram()
    res = vloop.solve(mech)
    th2, w2, a2 = crank_motion(mech)
    A = 2.0 * np.exp(1j * th2)
    B = A + 4.0
    ref = vloop.Result.from_arrays(
        mech.name,
        "closed form",
        mech.times,
        links={"crank": (th2, w2, a2), "rocker": (th2, w2, a2), "coupler": (np.zeros_like(th2),) * 3},
        points={
            "A": (A.real, A.imag, (1j * w2 * A).real, (1j * w2 * A).imag, *_acc(A, w2, a2)),
            "B": (B.real, B.imag, (1j * w2 * A).real, (1j * w2 * A).imag, *_acc(A, w2, a2)),
        },
    )
    # 1e-9 of each quantity's peak; a quantity that is zero in theory (the coupler's ω, α) gets 1e-9 of its
    # group's peak (measured: 8e-11 of the angular accelerations' peak at the sample nearest a folding)
    assert_histories_close(res, ref, rtol=1e-9, floor=1e-9, min_columns=15)
    # the three foldings θ2 = π, 2π, 3π are reported, to 1e-9 rad, each continued on the smooth branch
    cps = res.meta["change_points"]
    assert [round(c["inputs"]["θ_crank"] / math.pi) for c in cps] == [1, 2, 3]
    for c in cps:
        assert abs(c["inputs"]["θ_crank"] - round(c["inputs"]["θ_crank"] / math.pi) * math.pi) < 1e-9
        assert c["continued"] == "smooth" and c["loop"] == 1
    marked = np.nonzero(res.health["change_point"])[0]
    for c in cps:  # the first sample after each change point is marked in health
        assert int(np.searchsorted(res.t, c["time"])) in marked
    assert np.max(np.abs(np.diff(res["rocker.omega"]) - np.diff(w2))) < 1e-9  # no jump


def _acc(A: np.ndarray, w: np.ndarray, al: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    acc = (1j * al - w * w) * A
    return acc.real, acc.imag


@pytest.mark.parametrize("step", [0.01, 0.05, math.pi / 8])
def test_parallelogram_any_sampling_no_jump(step):
    """Coarse or exact-hitting samplings (π/8 s puts samples exactly on the foldings at ω = 2, α = 0)."""
    mech = parallelogram(alpha=0.0, step=step)
    res = vloop.solve(mech)
    th2, _, _ = crank_motion(mech)
    assert np.max(np.abs(res["rocker.theta"] - th2)) < 1e-9
    assert np.max(np.abs(res["rocker.omega"] - 2.0)) < 1e-9
    assert np.max(np.abs(res["coupler.omega"])) < 1e-9
    assert np.max(np.abs(res["rocker.alpha"])) < 1e-8  # α ≡ 0: measured 3e-11 at the worst sample
    assert len(res.meta["change_points"]) == 3


def test_the_file_picks_the_other_branch_after_a_change_point():
    """[solver] change_points = { 1 = ["other", "smooth"] }: anti-parallelogram after the first folding."""
    mech = parallelogram(alpha=0.0, step=0.01, solver='[solver]\nchange_points = { 1 = ["other", "smooth"] }')
    res = vloop.solve(mech)
    th2, _, _ = crank_motion(mech)
    A = 2.0 * np.exp(1j * th2)
    B1 = A + 4.0
    u = (4.0 - A) / np.abs(4.0 - A)
    B2 = A + u * u * np.conj(B1 - A)  # the mirror image in the line A–O4
    after = th2 > math.pi
    B = np.where(after, B2, B1)
    got = res["B.x"] + 1j * res["B.y"]
    assert np.max(np.abs(got - B)) < 1e-9 * mech.scale
    assert [c["continued"] for c in res.meta["change_points"]] == ["other", "smooth", "smooth"]


ISOSCELES = """
name = "isosceles"
[joints]
O2 = [0.0, 0.0]
A = [{ax!r}, {ay!r}]
B = [{bx!r}, 0.0]
[links]
ground = {{ joints = ["O2"], ground = true }}
crank = {{ joints = ["O2", "A"] }}
rod = {{ joints = ["A", "B"] }}
[sliders]
blk = {{ joint = "B", guide = "ground", axis = [1.0, 0.0] }}
[[drivers]]
link = "crank"
omega = {omega!r}
[time]
start = 0.0
stop = 2.0
step = 0.1
"""


def test_isosceles_slider_crank_passes_its_change_point_with_a_sample_on_it():
    omega = math.pi / 2 - 0.3  # sample 10 (t = 1 s) is at θ2 = π/2, on the change point
    mech = vloop.loads(ISOSCELES.format(ax=math.cos(0.3), ay=math.sin(0.3), bx=2 * math.cos(0.3), omega=omega))
    res = vloop.solve(mech)
    th = res["crank.theta"]
    assert np.max(np.abs(res["blk.s"] - 2 * np.cos(th))) < 1e-12
    assert np.max(np.abs(res["blk.v"] + 2 * omega * np.sin(th))) < 1e-9
    assert np.max(np.abs(res["blk.a"] + 2 * omega**2 * np.cos(th))) < 1e-9
    assert np.max(np.abs(res["rod.omega"] + omega)) < 1e-9  # the rod mirrors the crank: θ3 = −θ2
    (cp,) = res.meta["change_points"]
    assert abs(cp["inputs"]["θ_crank"] - math.pi / 2) < 1e-9 and abs(cp["time"] - 1.0) < 1e-9
    assert res.health["change_point"][10] == 1


def kite(a: float, d: float, th0: float, omega: float, stop: float, step: float) -> vloop.Mechanism:
    """Crank = coupler = a, rocker = ground = d, the crank at θ0 at t = 0 turning at ω; B from :func:`_kite_B`."""
    A0 = complex(a * np.exp(1j * th0))
    B0 = complex(_kite_B(A0, d))
    return vloop.loads(f"""
name = "kite"
[joints]
O2 = [0.0, 0.0]
O4 = [{d}, 0.0]
A = [{A0.real!r}, {A0.imag!r}]
B = [{B0.real!r}, {B0.imag!r}]
[links]
ground = {{ joints = ["O2", "O4"], ground = true }}
crank = {{ joints = ["O2", "A"] }}
coupler = {{ joints = ["A", "B"] }}
rocker = {{ joints = ["O4", "B"] }}
[[drivers]]
link = "crank"
omega = {omega!r}
[time]
start = 0.0
stop = {stop!r}
step = {step!r}
""")


def test_kite_passes_both_foldings_per_turn():
    a, d = 1.0, 2.5
    th0 = 0.7
    res = vloop.solve(kite(a, d, th0, 1.5, 8.0, 0.004))
    th2 = th0 + 1.5 * res.t
    B = _kite_B(a * np.exp(1j * th2), d)
    assert np.max(np.abs(res["B.x"] + 1j * res["B.y"] - B)) < 1e-9 * d
    # velocities against central differences of the closed form (h = 1e-5 s: error ~1e-10)
    h = 1e-5
    vB = (_kite_B(a * np.exp(1j * (th2 + 1.5 * h)), d) - _kite_B(a * np.exp(1j * (th2 - 1.5 * h)), d)) / (2 * h)
    assert np.max(np.abs(res["B.vx"] + 1j * res["B.vy"] - vB)) < 1e-6 * np.max(np.abs(vB))
    folds = [c["inputs"]["θ_crank"] / math.pi for c in res.meta["change_points"]]
    assert np.allclose(folds, np.round(folds), atol=1e-9) and len(folds) == 4  # π, 2π, 3π, 4π within 0.7 + 12 rad


def _kite_B(A: np.ndarray, d: float) -> np.ndarray:
    """O2 mirrored in the line A–O4."""
    u = (d - A) / np.abs(d - A)
    return A + u * u * np.conj(0.0 - A)


def test_a_near_parallelogram_is_not_a_change_point():
    """Rocker 2.001: the branches never meet (gap ~1e-3 of the size); the motion stays on its t = 0 branch,
    which the closed form (law of cosines, fixed branch) gives."""
    from validators.analytic import fourbar as analytic_fourbar

    text = PARALLELOGRAM.format(alpha=0.0, stop=1.5 * math.pi, step=0.01, solver="").replace(
        'rocker = { joints = ["O4", "B"] }', 'rocker = { joints = ["O4", "B"], length = 2.001 }'
    )
    mech = vloop.loads(text)
    res = vloop.solve(mech)
    assert res.meta["change_points"] == []
    assert_histories_close(res, analytic_fourbar.solve(mech), rtol=1e-9, min_columns=15)


def test_cli_reports_change_points(tmp_path, capsys):
    f = tmp_path / "p.toml"
    f.write_text(PARALLELOGRAM.format(alpha=0.0, stop=1.5 * math.pi, step=0.01, solver=""))
    assert main(["run", str(f), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert out.count("change point: loop 1 (O2–A–B–O4)") == 3 and "θ_crank = 3.141592654" in out
    health = np.genfromtxt(tmp_path / "o" / "health.csv", delimiter=",", names=True)
    assert health["healthchange_point"].sum() >= 3
    assert main(["info", str(f)]) == 0
    assert capsys.readouterr().out.count("change point: loop 1") == 3


def test_bad_change_point_option(tmp_path):
    with pytest.raises(vloop.MechanismError, match="change_points"):
        parallelogram(solver='[solver]\nchange_points = { 1 = "sideways" }')


@pytest.mark.parametrize(
    ("index", "why"),
    [
        (515, "a fast crank (0.12 rad a sample): its folding at 3π fell between grid points of the first zoom"),
        (336, "a change point between the first two samples"),
    ],
)
def test_corpus_change_points_found_by_the_nightly(index, why):
    """Seed 2026 of the generated corpus (vloop corpus): both once missed a change point and jumped
    branches silently; the velocity-continuous closed form (validators/analytic/changepoint.py) is the
    reference, and Pinocchio (which passes a change point on its predicted path) agrees too."""
    from validators import analytic, corpus, pinocchio

    mech = corpus.draw_item(2026, index).item.mechanism
    res = vloop.solve(mech)
    assert res.meta["change_points"], why
    assert_histories_close(res, analytic.solve(mech), rtol=1e-9, floor=1e-9, min_columns=15)
    if index == 515:
        pytest.importorskip("pinocchio")
        assert_histories_close(pinocchio.solve(mech), res, rtol=1e-9, floor=1e-9, min_columns=15)


@pytest.mark.parametrize(
    "index,why",
    [
        (
            138,
            "a kite whose ground chord, summed from pivots far from the origin, left a 1e-15 gap at its change point",
        ),
        (7626, "a kite: the rates at the sample 0.014 rad from its change point were off by 2.8e-9"),
        (7642, "a change-point four-bar: the rates 0.011 rad from its change point were off by 2.6e-9"),
    ],
)
def test_corpus_seed_9191_through_its_change_points(index, why):
    """Seed 9191 of the generated corpus, where vloop was the odd one out: it runs through every change point
    (the first stopped at one, "a limit position"), on the closed form continued through them
    (validators/analytic/changepoint.py) to 1e-9 (the validation's tolerance)."""
    from validators import analytic, corpus

    mech = corpus.draw_item(9191, index).item.mechanism
    res = vloop.solve(mech)
    assert len(res.t) == len(mech.times) and res.meta["change_points"], why
    assert_histories_close(res, analytic.solve(mech), rtol=1e-9, floor=1e-9, min_columns=15)


# ---------------------------------------------------------------- beside a change point, every generated family
#
# The reference is the four-bar's closed form (law of cosines for B: its foot p = (b² − c² + f²)/(2f) along A→O4 and
# its height σ·√(b² − p²); ω3, ω4 and α3, α4 from the loop's velocity and acceleration equations, two real
# equations each), evaluated in 60-digit decimal arithmetic on the linkage the file states: its stated crank,
# coupler and rocker lengths, O2 and the ground's direction from its coordinates, and the ground length that makes
# s + l = p + q exact (the coordinates give it to within an ulp; beside a change point that ulp moves the
# velocities by ε·cond², so the float closed form — validators/analytic/changepoint.py — is itself off by up to
# 1e-4 at 1e-6 rad and cannot be evaluated at 1e-9 rad). The branch σ (which side of A→O4 B is on, flipped at each
# change point: the velocity-continuous motion) and the change angles are the validators'
# (analytic_changepoint.branch_signs, change_angles).

DIGITS = 60


def _cos_sin(x: float) -> tuple:
    from decimal import Decimal, localcontext

    with localcontext() as ctx:
        ctx.prec = DIGITS + 10
        pi = Decimal(
            "3.14159265358979323846264338327950288419716939937510582097494459230781640628620899862803482534211706798"
        )
        x = Decimal(x)
        x -= 2 * pi * (x / (2 * pi)).to_integral_value()
        c = s = Decimal(0)
        term, n = Decimal(1), 0
        while abs(term) > Decimal(10) ** -(DIGITS + 5):
            if n % 4 == 0:
                c += term
            elif n % 4 == 1:
                s += term
            elif n % 4 == 2:
                c -= term
            else:
                s -= term
            n += 1
            term = term * x / n
        return +c, +s


def _fourbar_hp(geometry: dict, sigma: int, theta: float, omega: float, alpha: float) -> dict[str, float]:
    """The four-bar at crank angle θ (ω, α): B, the coupler's and rocker's ω, α and B's velocity and acceleration."""
    from decimal import Decimal, localcontext

    with localcontext() as ctx:
        ctx.prec = DIGITS
        a, b, c, O2, O4 = (geometry[k] for k in ("a", "b", "c", "O2", "O4"))
        ca, sa = _cos_sin(theta)
        w2, al2 = Decimal(omega), Decimal(alpha)
        A = (O2[0] + a * ca, O2[1] + a * sa)
        dx, dy = O4[0] - A[0], O4[1] - A[1]
        f2 = dx * dx + dy * dy
        f = f2.sqrt()
        p = (b * b - c * c + f2) / (2 * f)
        q2 = b * b - p * p
        q = q2.sqrt() if q2 > 0 else Decimal(0)
        ux, uy = dx / f, dy / f
        B = (A[0] + p * ux - sigma * q * uy, A[1] + p * uy + sigma * q * ux)
        e3 = ((B[0] - A[0]) / b, (B[1] - A[1]) / b)
        e4 = ((B[0] - O4[0]) / c, (B[1] - O4[1]) / c)

        def solve(rx: Decimal, ry: Decimal) -> tuple:  # b·e3·x3 − c·e4·x4 = r (two real equations)
            det = -b * e3[0] * c * e4[1] + c * e4[0] * b * e3[1]
            return (-rx * c * e4[1] + c * e4[0] * ry) / det, (b * e3[0] * ry - rx * b * e3[1]) / det

        w3, w4 = solve(-a * w2 * ca, -a * w2 * sa)  # j·(a·ω2·e2 + b·ω3·e3 − c·ω4·e4) = 0
        Rx = a * w2 * w2 * ca + b * w3 * w3 * e3[0] - c * w4 * w4 * e4[0]  # the centripetal terms
        Ry = a * w2 * w2 * sa + b * w3 * w3 * e3[1] - c * w4 * w4 * e4[1]
        al3, al4 = solve(-a * al2 * ca + Ry, -a * al2 * sa - Rx)
        out = {
            "B.x": B[0],
            "B.y": B[1],
            "coupler.omega": w3,
            "rocker.omega": w4,
            "coupler.alpha": al3,
            "rocker.alpha": al4,
            "B.vx": -c * w4 * e4[1],
            "B.vy": c * w4 * e4[0],
            "B.ax": -c * al4 * e4[1] - c * w4 * w4 * e4[0],
            "B.ay": c * al4 * e4[0] - c * w4 * w4 * e4[1],
        }
        return {k: float(v) for k, v in out.items()}


def _stated_geometry(mech: vloop.Mechanism) -> dict:
    """The linkage the file states (see above), in Decimal: a, b, c, O2, O4 (d from s + l = p + q)."""
    from decimal import Decimal, localcontext

    from validators.analytic import fourbar as analytic_fourbar

    roles = analytic_fourbar.roles(mech)
    d_file = analytic_fourbar.dims(mech, roles).d
    lengths = {lk.name: lk.length for lk in mech.links.values()}
    with localcontext() as ctx:
        ctx.prec = DIGITS
        a, b, c = (Decimal(lengths[n]) for n in (roles.crank, roles.coupler, roles.rocker))
        d = min(
            (x for x in (b + c - a, a + abs(b - c), a - abs(b - c)) if x > 0), key=lambda x: abs(x - Decimal(d_file))
        )
        O2 = tuple(Decimal(v) for v in mech.joints[roles.O2])
        ux, uy = (Decimal(v) - o for v, o in zip(mech.joints[roles.O4], O2, strict=True))
        n = (ux * ux + uy * uy).sqrt()
        return {"a": a, "b": b, "c": c, "O2": O2, "O4": (O2[0] + d * ux / n, O2[1] + d * uy / n), "roles": roles}


def _times_at(mech: vloop.Mechanism, crank_angle: float) -> float:
    d = mech.drivers[0]
    return (crank_angle - d.x0) / d.v0


CP_FAMILIES = ("parallelogram", "antiparallelogram", "kite", "change-point")
CP_DRAWS = 3  # mechanisms per family
CP_DISTANCES = (1e-3, 1e-6, 1e-9)  # rad of crank from the change point, either side


@pytest.mark.parametrize("family", CP_FAMILIES)
def test_rates_beside_a_change_point_every_generated_family(family):
    """Each family of the generated corpus (seed 4242, CP_DRAWS mechanisms), the crank turned either way, sampled on
    the file's times plus samples 1e-3, 1e-6 and 1e-9 rad either side of its first change point — and those six
    alone (a late start: the stencil lies on the file's motion, not on the lead-in path). Against the 60-digit
    closed form of the stated linkage (above), each quantity relative to its group's scale (ω_max for link rates,
    ω_max² + α_max for link accelerations; the size L, ω_max·L, (ω_max² + α_max)·L for B):
    * the links' ω and α to rtol = 1e-9 (measured ≤ 1.8e-10; the float closed form 1e-4 at 1e-6 rad);
    * B's position, velocity and acceleration to rtol plus twice B's travel over the sample's distance Δθ from the
      change point (|dB/dθ|·Δθ of L): at 1e-9 rad the branches lie within round-off of each other (h within its
      round-off counts as 0), so B is placed at the change point itself (measured ≤ 9.3e-10; the float closed
      form 1.2e-8)."""
    from validators import corpus
    from validators.analytic import changepoint as analytic_changepoint
    from validators.analytic.common import cross

    checked = 0
    for index in range(CP_DRAWS):
        base = corpus.draw_item(4242, index, families=[f"fourbar/{family}"], limit_fraction=0.0).item.mechanism
        for sense in (1.0, -1.0):
            drv = base.drivers[0]
            mech = dataclasses.replace(base, drivers=(dataclasses.replace(drv, v0=sense * abs(drv.v0), a0=0.0),))
            geo = _stated_geometry(mech)
            roles = geo["roles"]
            zO4, zA, zB = (complex(*mech.joints[j]) for j in (roles.O4, roles.A, roles.B))
            sigma0 = float(np.sign(cross(zO4 - zA, zB - zA)))
            angles = analytic_changepoint.change_angles(mech)
            c = angles[0]
            turn = math.floor((drv.x0 - c) / (2 * math.pi)) + (1 if sense > 0 else 0)  # the first crossing ahead
            at = np.array([c + 2 * math.pi * turn + s * x for x in CP_DISTANCES for s in (-1, 1)])
            samples = np.sort(np.array([_times_at(mech, x) for x in at]))
            whole = vloop.solve(mech)
            w = max(np.max(np.abs(whole[f"{k}.omega"])) for k in ("crank", "coupler", "rocker"))
            acc = w * w + max(np.max(np.abs(whole[f"{k}.alpha"])) for k in ("crank", "coupler", "rocker"))
            L = mech.scale
            scale = {"omega": w, "alpha": acc, "x": L, "y": L, "vx": w * L, "vy": w * L, "ax": acc * L, "ay": acc * L}
            for times in (np.unique(np.concatenate([mech.times, samples])), samples):
                res = vloop.solve(mech, times)
                for t in samples:
                    k = int(np.searchsorted(res.t, t))
                    th = res["crank.theta"][k]
                    sigma = analytic_changepoint.branch_signs(np.array([drv.x0, th]), 0, sigma0, angles)[1]
                    ref = _fourbar_hp(geo, int(sigma), th, res["crank.omega"][k], res["crank.alpha"][k])
                    away = abs(math.remainder(th - c, 2 * math.pi))
                    lever = math.hypot(ref["B.vx"], ref["B.vy"]) / abs(res["crank.omega"][k]) / L  # |dB/dθ| / L
                    for q, value in ref.items():
                        tol = 1e-9 + (2 * lever * away if q.startswith("B.") else 0.0)
                        err = abs(res[q][k] - value) / scale[q.split(".")[1]]
                        assert err <= tol, (
                            f"{family} #{index} ω {sense:+g} at {away:.0e} rad, {q}: {err:.2e} > {tol:.2e}"
                        )
                    checked += 1
    assert checked == CP_DRAWS * 2 * 2 * 2 * len(CP_DISTANCES)


# ---------------------------------------------------------------- a change point in the first or last sample interval
#
# Seed 4711's mechanism 943 (vloop corpus): an antiparallelogram-family four-bar (crank = rocker, coupler = ground),
# change points at the crank angles π/2 and 3π/2, started 0.054 rad before 3π/2 with samples 0.109 rad apart: the
# change point lay at 0.495 of the first interval, where the discriminant's two samples are alike (its √h is a V
# with the vertex near the middle), and vloop went on along the parallelogram branch (the coupler's ω from 30.3 to 0).


def _antiparallelogram_at(theta0: float, omega: float, step: float, n: int) -> vloop.Mechanism:
    """Seed 4711's mechanism 943 with its crank at θ0 (rad), on the antiparallelogram branch (the coupler not parallel
    to the ground), driven at ω (rad/s), n samples ``step`` (s) apart from t = 0. B is the circles' intersection
    (law of cosines along A→O4), from the file's lengths and pivots."""
    from validators import corpus

    base = corpus.draw_item(4711, 943).item.mechanism
    a, b, c = (base.links[k].length for k in ("crank", "coupler", "rocker"))
    O2, O4 = (complex(*base.joints[k]) for k in ("O2", "O4"))
    A = O2 + a * complex(math.cos(theta0), math.sin(theta0))
    f = abs(O4 - A)
    u = (O4 - A) / f
    p = (b * b - c * c + f * f) / (2 * f)
    q = math.sqrt(max(b * b - p * p, 0.0))
    B = max((A + (p + 1j * s * q) * u for s in (1, -1)), key=lambda z: abs(((z - A) * (O4 - O2).conjugate()).imag))
    text = f"""
name = "antiparallelogram-edge"
drivers = [{{ link = "crank", pivot = "O2", omega = {omega!r}, alpha = 0.0 }}]
[joints]
O2 = [{O2.real!r}, {O2.imag!r}]
O4 = [{O4.real!r}, {O4.imag!r}]
A = [{A.real!r}, {A.imag!r}]
B = [{B.real!r}, {B.imag!r}]
[links]
ground = {{ joints = ["O2", "O4"], ground = true }}
crank = {{ joints = ["O2", "A"], length = {a!r} }}
coupler = {{ joints = ["A", "B"], length = {b!r} }}
rocker = {{ joints = ["O4", "B"], length = {c!r} }}
[time]
start = 0.0
stop = {step * (n - 1)!r}
step = {step!r}
"""
    return vloop.loads(text)


def _edge_cases() -> list:
    cases = []
    for sense in (1, -1):
        for where in ("first", "last"):
            for frac in (0.02, 0.3, 0.48, 0.49, 0.495, 0.5, 0.505, 0.51, 0.52, 0.7, 0.98):  # (near ½: the two alike)
                cases.append(pytest.param(sense, where, frac, id=f"{where}-{frac}-{'up' if sense > 0 else 'down'}"))
    return cases


@pytest.mark.parametrize(("sense", "where", "frac"), _edge_cases())
def test_change_point_inside_the_first_or_last_interval(sense, where, frac):
    """The change point 3π/2 inside the first (or the last) sample interval, at ``frac`` of it from the interval's
    start, the crank turning either way: vloop continues on the velocity-continuous branch, and health flags the
    first sample past the crossing (and at most the one before it, where that sample's rates were taken across the
    change point). Against the closed form continued through change points (validators/analytic/changepoint.py,
    the nightly validation's reference) to its tolerance, 1e-9 of each column's peak, for positions, angles and
    rates; accelerations against the 60-digit closed form of the stated linkage (above) to 1e-9 of the group's
    scale, since the float closed form is off by 1.5e-8 of its peak α at 0.002 rad from the change point (vloop:
    7e-12 there)."""
    from validators import analytic
    from validators.analytic import changepoint as analytic_changepoint
    from validators.analytic.common import cross

    omega, cp, n, step = sense * 7.424019735557147, 1.5 * math.pi, 12, 0.0147  # (the nightly's: 0.109 rad a step)
    back = (frac if where == "first" else n - 2 + frac) * abs(omega) * step  # rad from θ0 to the change point
    mech = _antiparallelogram_at(cp - sense * back, omega, step, n)
    res = vloop.solve(mech)
    assert len(res.t) == n
    motion = [c for c in res.columns if c != "t" and not c.endswith((".alpha", ".ax", ".ay"))]
    assert_histories_close(res, analytic.solve(mech), rtol=1e-9, floor=1e-9, columns=motion, min_columns=15)
    assert [c["inputs"]["θ_crank"] for c in res.meta["change_points"]] == pytest.approx([cp], abs=1e-9)
    row = int(np.searchsorted(res.t, back / abs(omega)))  # the first sample past the crossing, flagged; so may be
    flagged = np.flatnonzero(res.health["change_point"]).tolist()  # the one before, if its rates came across it
    assert row in flagged and set(flagged) <= {row - 1, row}, flagged

    geo = _stated_geometry(mech)
    zO4, zA, zB = (complex(*mech.joints[j]) for j in (geo["roles"].O4, geo["roles"].A, geo["roles"].B))
    sigma0, angles = float(np.sign(cross(zO4 - zA, zB - zA))), analytic_changepoint.change_angles(mech)
    sigma = analytic_changepoint.branch_signs(res["crank.theta"], 0, sigma0, angles)
    ref = [_fourbar_hp(geo, int(sigma[k]), res["crank.theta"][k], omega, 0.0) for k in range(n)]
    acc = max(abs(r[f"{k}.alpha"]) for r in ref for k in ("coupler", "rocker")) + omega**2
    for q in ("coupler.alpha", "rocker.alpha", "B.ax", "B.ay"):
        scale = acc * (mech.scale if q.startswith("B.") else 1.0)
        err = np.max(np.abs(res[q] - [r[q] for r in ref])) / scale
        assert err <= 1e-9, f"{q}: {err:.2e} of (ω² + α)max"


def test_the_nightly_antiparallelogram_through_its_first_interval():
    """Seed 4711's mechanism 943 itself (the change point at 0.495 of its first interval, and again at 5π/2 inside
    the run): on the closed form to the validation's 1e-9, both change points flagged in health."""
    from validators import analytic, corpus

    mech = corpus.draw_item(4711, 943).item.mechanism
    res = vloop.solve(mech)
    assert_histories_close(res, analytic.solve(mech), rtol=1e-9, floor=1e-9, min_columns=15)
    assert np.ptp(res["coupler.theta"][:3]) > 0.5  # (not the parallelogram branch, where it stays at 3π/2)
    d = mech.drivers[0]
    crossings = [(x - d.x0) / d.v0 for x in (1.5 * math.pi, 2.5 * math.pi)]
    assert set(np.searchsorted(res.t, crossings).tolist()) <= set(np.flatnonzero(res.health["change_point"]).tolist())
