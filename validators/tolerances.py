"""Every tolerance of the cross-validation, in one place, with where each number comes from.

A comparison passes when, for every shared quantity, max |a − b| ≤ atol + rtol·peak, where
peak is the quantity's peak magnitude over the run and atol = floor × the peak of its group
(see :mod:`vloop.compare`; ``floor`` below). ``rtol`` is a number or a dict by quantity group.

Two allowances depend on the run, each derived below from what the engines report, sample by sample:
the conditioning floor next to a change point or a toggle (:func:`conditioning_floor`, from the unit-free
condition numbers of :func:`condition_number`), and the round-off of Exudyn's index-3 time integration
(:func:`integrator_roundoff`, from its step and its conditioning). A pair of engines without a stated
tolerance (compared only to find the odd one out) gets :func:`pair_tolerance`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

GROUPS = ("angle", "angular velocity", "angular acceleration", "position", "velocity", "acceleration")
GROUPS += ("force", "moment")  # kinetostatics (vloop.forces): reactions [N], torques and moments [N·m]


@dataclass(frozen=True)
class Tolerance:
    """rtol: fraction of each quantity's peak; floor: absolute allowance as a fraction of its group's peak."""

    rtol: float | dict[str, float]
    note: str
    floor: float | dict[str, float] = 1e-12

    def as_dict(self) -> dict[str, Any]:
        def by_group(x: float | dict[str, float]) -> dict[str, float]:
            return x if isinstance(x, dict) else {g: x for g in GROUPS}

        return {"rtol": by_group(self.rtol), "floor": by_group(self.floor), "note": self.note}


# Exudyn's real time integration (index-3 generalized-alpha, spectral radius 0.6, second order in h),
# at the step validators/exudyn.py picks for an accuracy target of 1e-5: measured on the catalog
# (max error / group peak) ≤ 2e-15 positions and angles (the constraints fix them), ≤ 1e-6 velocities,
# ≤ 6e-6 accelerations. Allowed: 1e-9, 3e-6, 2e-5 of the group's peak — the same figure as the floor,
# because a quantity that is zero in theory (a horizontal slider's vy) carries the integrator's error too.
_DYNAMIC_RTOL = {
    "angle": 1e-9,
    "position": 1e-9,
    "angular velocity": 3e-6,
    "velocity": 3e-6,
    "angular acceleration": 2e-5,
    "acceleration": 2e-5,
    # Forces carry the accelerations' error (m·a, I·α) and Exudyn's multipliers converge with them:
    # measured <= 7e-6 of the group peak on the catalog files with masses; allowed as accelerations.
    "force": 2e-5,
    "moment": 2e-5,
}
_DYNAMIC = Tolerance(
    _DYNAMIC_RTOL,
    "Exudyn SolveDynamic (generalized-alpha, rho = 0.6): two runs at h and 2h Richardson-extrapolated, h four "
    "times the step of the accuracy target 1e-5, the first samples from one run at that step: measured <= 1e-6 "
    "velocities and <= 6e-6 accelerations of the group peak on the catalog for the single run, <= 2e-7 for the "
    "extrapolation; allowed 3e-6 / 2e-5, as rtol and as floor, plus the run's own round-off bound "
    "(integrator_roundoff); in vloop validate on the samples a single run's first 10,000 steps reach.",
    floor=_DYNAMIC_RTOL,
)

# Exudyn's time integration costs ~20-40 µs a step (generalized-α on a planar model of ≤ 10 bodies; a four-bar's
# ~19 µs with Eigen's dense LU and the inputs evaluated by Exudyn, validators/exudyn.py), and
# the step its accuracy asks for makes the corpus's runs 6,000 steps at the median and 280,000 at the most (a
# tail that was 80 % of a corpus validation's time). The harness compares it on the samples a single run's first
# DYNAMIC_STEPS steps reach: 70 % of the corpus's runs whole, the others' first part (each comparison says on
# how many of its samples), integrated by the extrapolated pair in about 40 % of those steps; the kinematic
# engines compare every sample.
DYNAMIC_STEPS = 10_000

# For a quantity that is zero in theory (a fixed point's acceleration, a translating coupler's ω) the
# allowance is a fraction of its group's peak. Away from singular configurations both sides agree to
# round-off (~1e-13 of the group's peak); next to a change point or toggle the rates carry up to cond³·ε
# (vloop's documented error bound, flagged in health): measured ≤ 3e-10 of the group's peak on the
# generated change-point four-bars (seed 2026). The floor is 1e-9 of the group's peak, the claim itself.
_FLOOR = 1e-9

# MuJoCo's simulation of the exported MJCF (validators/mujoco.py): soft equality constraints (impedance 0.9999,
# time constant two steps) and a servo on the input, RK4 at a step that moves the input 1 mrad (or 1e-3 of the size).
# Positions carry the constraints' gap and the servo's lag, both O(h²) and both reported per sample (the run's
# allowance adds them, through the linkage's largest velocity ratio); the rates carry the step's O(h) error.
# Measured on the catalog (max error / size, rad): ≤ 3.6e-8 positions and 1.3e-7 angles (4.2e-7 and 7.8e-7 next
# to a limit position), ≤ 2.7e-5 of the peak for rates (6.2e-5 next to a limit). Allowed: 1e-6 of the peak for
# positions and angles (the aim: 1e-6 of the size), 1e-3 for rates (the input's move per step: a follower next to a
# change point turns many times faster than the input, and its rates' O(h) error with it: up to 5e-4 measured on
# a generated corpus, seed 39); no accelerations or forces.
_MUJOCO_RTOL = {"angle": 1e-6, "position": 1e-6, "angular velocity": 1e-3, "velocity": 1e-3}
_MUJOCO_RTOL |= {g: 1e-3 for g in GROUPS if g not in _MUJOCO_RTOL}  # groups it has no column of (never compared)
_MUJOCO = Tolerance(
    _MUJOCO_RTOL,
    "MuJoCo simulating the exported MJCF (RK4, soft connect constraints d = 0.9999, tc = 2 steps, a servo on the "
    "input; the step moves it 1 mrad): positions and angles 1e-6 of the peak plus the run's reported gap and "
    "lag, rates 1e-3 (measured <= 7.8e-7 and <= 6.2e-5 on the catalog); no accelerations.",
    floor=_MUJOCO_RTOL,
)

# (engine, reference) -> tolerance
TOLERANCES: dict[tuple[str, str], Tolerance] = {
    ("analytic", "vloop"): Tolerance(
        1e-9,
        "Closed forms derived by hand; both sides are exact to round-off and agree to ~1e-13 of peak "
        "(measured: ≤ 1e-13 on the catalog). 1e-9 is the claim of the core issue.",
        floor=_FLOOR,
    ),
    ("pinocchio", "vloop"): Tolerance(
        1e-9,
        "Pinocchio's Newton projection stops at a step of 1e-10 (scaled) then solves exact linear systems; "
        "measured ≤ 3e-13 of peak on the catalog. 1e-9 leaves four orders of margin.",
        floor=_FLOOR,
    ),
    ("pinocchio", "analytic"): Tolerance(1e-9, "As pinocchio vs vloop; measured ≤ 3e-13.", floor=_FLOOR),
    ("exudyn-kinematic", "vloop"): Tolerance(
        1e-8,
        "Newton on Exudyn's own constraint residuals and Jacobians, stopped at ~1e-12; the claim is 1e-8.",
        floor=_FLOOR,
    ),
    ("exudyn-kinematic", "analytic"): Tolerance(1e-8, "As exudyn-kinematic vs vloop.", floor=_FLOOR),
    ("exudyn-dynamic", "vloop"): _DYNAMIC,
    ("exudyn-dynamic", "analytic"): _DYNAMIC,
    ("mujoco", "vloop"): _MUJOCO,
    ("mujoco", "analytic"): _MUJOCO,
}


def tolerance(engine: str, reference: str) -> Tolerance:
    """The tolerance for comparing ``engine`` against ``reference`` (KeyError if none is stated)."""
    return TOLERANCES[(engine, reference)]


def pair_tolerance(engine: str, reference: str) -> Tolerance:
    """The tolerance between two engines, stated or derived through vloop (the common reference).

    Used when the engines disagree and every pair is compared to find the odd one out
    (validators.consensus). A pair without a stated entry (Exudyn's time integration against
    Pinocchio, say) gets the sum of the two engines' tolerances against vloop, group by group, for
    rtol and floor alike: if |a − v| ≤ floor_a·G + rtol_a·P and |b − v| ≤ floor_b·G + rtol_b·P, the
    triangle inequality gives |a − b| ≤ (floor_a + floor_b)·G + (rtol_a + rtol_b)·P, where P is the
    quantity's peak and G its group's (the peaks of a, b and v differ by less than the errors, a
    second-order change of the allowance). Two engines each right within its claim are right within
    this one; a pair beyond it has at least one engine outside its claim.
    """
    stated = TOLERANCES.get((engine, reference)) or TOLERANCES.get((reference, engine))
    if stated is not None:
        return stated
    a, b = tolerance(engine, "vloop").as_dict(), tolerance(reference, "vloop").as_dict()
    return Tolerance(
        {g: a["rtol"][g] + b["rtol"][g] for g in GROUPS},
        f"{engine} vs {reference}: the sum of their tolerances against vloop (triangle inequality)",
        floor={g: a["floor"][g] + b["floor"][g] for g in GROUPS},
    )


# The rates' round-off next to a singular configuration, from the conditioning the engines report.
EPS = 2.220446049250313e-16  # double precision's unit round-off (numpy.finfo(float).eps)
# Linear solves each amplify relative error by the Jacobian's condition number κ (forward error bound
# |Δx|/|x| ≤ κ·|Δb|/|b| for a perturbation of the data at round-off): the positions come out of Newton
# (or a closed form) with error κ·ε of their group's peak; the velocities solve J·q̇ = b with J evaluated at
# those positions, κ·(κ·ε); the accelerations solve J·q̈ = −J̇·q̇ + … with both, κ·(κ²·ε); the forces are one
# more solve with Jᵀ over the accelerations, κ⁴·ε. Power of κ per group:
_KAPPA_POWER = {
    "angle": 1,
    "position": 1,
    "angular velocity": 2,
    "velocity": 2,
    "angular acceleration": 3,
    "acceleration": 3,
    "force": 4,
    "moment": 4,
}


def conditioning_floor(kappa: np.ndarray) -> dict[str, np.ndarray]:
    """The floor added per sample to every comparison, as a fraction of each group's peak: κ(t)^p·ε.

    ``kappa``: at each sample the largest of the unit-free condition numbers (:func:`condition_number`) the
    two engines compared report for their own formulations and vloop's for the loops (the configuration's,
    which a closed form suffers from too). Away from singular configurations κ ≲ 10² and this
    is below 1e-9 (the stated floor) for every group up to accelerations; next to a change point or a
    toggle it grows as the bound above: at κ = 510 (seed 2026, index 966: two samples from a change
    point) the accelerations may differ by 510³·ε = 2.9e-8 of their peak, and the closed form, Pinocchio
    and vloop differ there by 9.4e-9, 5.4e-9 and 4.0e-9 pairwise (each engine within the bound of the
    others, none near it elsewhere). The claim is this bound at each sample, not a looser tolerance.
    """
    kappa = np.nan_to_num(np.asarray(kappa, float), nan=np.inf, posinf=np.inf)
    return {g: np.minimum(kappa**p * EPS, 1.0) for g, p in _KAPPA_POWER.items()}


def condition_number(jacobian: np.ndarray, length_columns: np.ndarray, size: float) -> float:
    """The constraint Jacobian's condition number free of the file's units, as vloop's health reports it.

    A raw Jacobian mixes lengths and angles (∂C/∂x is a number, ∂C/∂θ a length; a driver's row is an
    angle), so its condition number changes with the units and the mechanism's size (a 30 m mechanism's is
    ~30× a 1 m one's). Here the angle columns are divided by the mechanism ``size`` (a turn measured as the
    length it moves a point at that distance) and every row by its largest entry (a row's units cancel).
    ``length_columns``: which columns are lengths (the others angles). ∞ for a singular Jacobian.
    """
    return float(condition_numbers(np.asarray(jacobian, float)[None], length_columns, size)[0])


def condition_numbers(jacobians: np.ndarray, length_columns: np.ndarray, size: float) -> np.ndarray:
    """:func:`condition_number` of every Jacobian of a stack (k, n, n) at once: the same numbers (numpy's SVD
    runs matrix by matrix on a stack), without the per-call overhead when an engine has one per sample."""
    J = np.array(jacobians, float)
    if len(J) == 0:
        return np.zeros(0)
    J[..., ~np.asarray(length_columns, bool)] /= size
    J /= np.maximum(np.max(np.abs(J), axis=-1, keepdims=True), 1e-300)
    kappa = np.linalg.cond(J)
    return np.where(np.isfinite(kappa), kappa, np.inf)


def integrator_roundoff(
    kappa: np.ndarray, length: float, size: float, angle: float, step: float, spectral_radius: float
) -> dict[str, np.ndarray]:
    """The round-off of Exudyn's index-3 generalized-α rates, per sample and group, in the file's units.

    The integrator fixes the positions by the constraints, to Newton's round-off: the residual is known to
    ε·L (L: the largest |x|, |y| of the run, Exudyn's coordinates being absolute) and an angle to ε·Φ (the
    largest |θ|), so the coordinates to δx ≈ κ·ε·L and δθ ≈ κ·ε·(L/size + Φ), κ the unit-free condition
    number of Exudyn's own constraint Jacobian at the sample (its kinematic pass; :func:`condition_number`).
    The accelerations are positions differenced twice over the step h: the Newmark update
    a = (q_{n+1} − q_n − h·v_n − …)/(β·h²) carries 2·δq/(β·h²), the solution acceleration (1 − α_m)/(1 − α_f)
    times that; the velocities γ/(β·h) times 2·δq. With ρ∞: α_m = (2ρ∞ − 1)/(ρ∞ + 1), α_f = ρ∞/(ρ∞ + 1),
    γ = ½ − α_m + α_f, β = ¼·(γ + ½)². A point also carries its body's angular error times its distance from
    the body's centre (≤ size): δx is doubled for the points. At the step the accuracy asks for this is far
    below the integrator's O(h²) error; it matters where the samples are much closer together than that
    step (a run of a millisecond): seed 2026, index 363 (samples 6.7 µs apart, next to a toggle).
    """
    rho = spectral_radius
    alpha_m, alpha_f = (2 * rho - 1) / (rho + 1), rho / (rho + 1)
    gamma = 0.5 - alpha_m + alpha_f
    beta = 0.25 * (gamma + 0.5) ** 2
    kappa = np.asarray(kappa, float)
    dq_len = 2.0 * kappa * EPS * length
    dq_ang = kappa * EPS * (length / size + max(angle, 1.0))
    acc = 2.0 * (1 - alpha_m) / (1 - alpha_f) / (beta * step * step)
    vel = 2.0 * gamma / (beta * step)
    return {
        "acceleration": acc * dq_len,
        "angular acceleration": acc * dq_ang,
        "velocity": vel * dq_len,
        "angular velocity": vel * dq_ang,
    }
