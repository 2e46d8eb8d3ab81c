"""Velocity ratio and mechanical advantage between the driver and an output link or slider.

With one driver of rate ẋ_in (a crank's ω [rad/s] or a driven slider's v [length/s]) and an
output of rate ẋ_out (a link's ω, or a slider's v along its guide):

    velocity ratio      VR = ẋ_out / ẋ_in
    mechanical advantage MA = 1/VR = ẋ_in / ẋ_out  (= T_out/T_in for two links)

MA follows from the power balance of a linkage with no losses (no friction, no inertia; the only
assumption): the input's power T_in·ω_in equals the power the output delivers, T_out·ω_out, so
T_out/T_in = ω_in/ω_out. Both ratios are signed (CCW and +axis positive): a negative ratio means
the output moves against the input's sense. Units follow the pair: link/link 1; slider output,
crank input: VR [length/rad], MA = F_out/T_in [1/length]; crank output, slider input: VR
[rad/length], MA = T_out/F_in [length]; slider/slider 1. Where the input is at rest the ratio of
the configuration is used (velocity coefficients, :func:`vloop.teaching._motion.unit_rate_result`).
MA is infinite where the output is exactly at rest (a dead centre of the output).
"""

from __future__ import annotations

import numpy as np

from ..errors import MechanismError
from ..model import Mechanism
from ..result import Result
from . import _motion


def output_rate_column(mech: Mechanism, output: str) -> str:
    """The Result column of an output's rate: ``NAME.v`` for a slider, ``NAME.omega`` for a link."""
    if isinstance(output, str) and output in mech.sliders:
        return f"{output}.v"
    if isinstance(output, str) and output in mech.links and not mech.links[output].ground:
        return f"{output}.omega"
    known = [n for n in mech.moving_links]
    raise MechanismError(
        f"{mech.name}: unknown output {str(output)[:60]!r} (a moving link or a slider: {', '.join(known)})",
        entry="outputs",
    )


def velocity_ratio(mech: Mechanism, result: Result, output: str) -> np.ndarray:
    """VR = ẋ_out/ẋ_in over the run, signed (module docstring for units): ω_out/ω_in for two links."""
    _motion.single_driver(mech, "a velocity ratio")
    col = output_rate_column(mech, output)
    rate_in = _motion.input_rate(mech, result)
    rest = _motion.at_rest(rate_in)
    out = np.empty(len(result.t))
    moving = ~rest
    out[moving] = result[col][moving] / rate_in[moving]
    if rest.any():
        out[rest] = _motion.unit_rate_result(mech, result)[col][rest]
    return out


def mechanical_advantage(mech: Mechanism, result: Result, output: str) -> np.ndarray:
    """MA = ẋ_in/ẋ_out over the run, signed, no losses (module docstring): T_out/T_in for two links.

    Infinite (numpy inf) where the output is exactly at rest.
    """
    vr = velocity_ratio(mech, result, output)
    with np.errstate(divide="ignore"):
        return 1.0 / vr


def default_outputs(mech: Mechanism) -> list[str]:
    """The outputs a course would name: every slider, then every link pivoted on the ground that is not driven."""
    driven = {d.target for d in mech.drivers}
    ground_joints = set(mech.links[mech.ground].joints)
    links = [
        n for n, lk in mech.links.items() if not lk.ground and n not in driven and ground_joints.intersection(lk.joints)
    ]
    return [s for s in mech.sliders if s not in driven] + links
