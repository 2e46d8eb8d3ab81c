"""Teaching quantities of a kinematics course, as pure functions over a Mechanism and its Result.

    import vloop
    mech = vloop.load("mechanisms/fourbar_textbook_example.toml")
    res = vloop.solve(mech)
    ic = vloop.instant_centres(mech, res)          # every pair: Kennedy's theorem + velocity field
    x, y, at_inf = ic.position("ground", "l3")     # I13 [length]; at infinity: (x, y) = direction
    mu = vloop.transmission_angles(mech, res)      # one per dyad: .raw, .folded, .pressure [rad]
    vr = vloop.velocity_ratio(mech, res, "l4")     # ω4/ω2; vloop.mechanical_advantage = ω2/ω4
    cyc = vloop.teaching.cycle(mech)               # one input cycle: dead centres, strokes, time ratios
    vloop.dead_centres(mech), vloop.time_ratio(mech, "l4"), vloop.stroke(mech, "l4")

Modules: :mod:`.centres` (instant centres), :mod:`.transmission` (dyads, transmission and pressure
angles), :mod:`.ratios` (velocity ratio, mechanical advantage), :mod:`.input_cycle` (dead centres,
toggles, time ratio, stroke), :mod:`.report` (the extras CSV, the ``vloop info`` summary, the
transmission-angle figure). Angles in rad, lengths in the file's units, time in s, CCW positive.
"""

from __future__ import annotations

from .centres import CentreSet, InstantCentres, instant_centres, kennedy_centres, velocity_centres
from .input_cycle import Cycle, OutputCycle, Rest, cycle, dead_centres, stroke, time_ratio
from .ratios import default_outputs, mechanical_advantage, velocity_ratio
from .report import extras, info_lines, plot_transmission_angles, write_extras
from .transmission import Dyad, TransmissionAngle, dyads, transmission_angles

__all__ = [
    "CentreSet",
    "Cycle",
    "Dyad",
    "InstantCentres",
    "OutputCycle",
    "Rest",
    "TransmissionAngle",
    "cycle",
    "dead_centres",
    "default_outputs",
    "dyads",
    "extras",
    "info_lines",
    "instant_centres",
    "kennedy_centres",
    "mechanical_advantage",
    "plot_transmission_angles",
    "stroke",
    "time_ratio",
    "transmission_angles",
    "velocity_centres",
    "velocity_ratio",
    "write_extras",
]
