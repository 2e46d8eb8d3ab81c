"""Forward dynamics on the loops: from torques, forces and springs to the motion (docs/dynamics.md).

    sim = vloop.simulate(mech)                     # the file's [dynamics]
    sim.result, sim.energy, vloop.dynamics.cycle(sim)

A consumer of the loop solve (the velocity coefficients) and of the file's mass properties; the
integrator is scipy's solve_ivp on (q, q̇); positions come from the loop solve, never integrated.
"""

from __future__ import annotations

from .equations import Model, compile_model
from .integrate import ENERGY_COLUMNS, Simulation, simulate

__all__ = ["ENERGY_COLUMNS", "Model", "Simulation", "compile_model", "simulate"]
