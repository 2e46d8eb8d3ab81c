"""What the studio says about a drawing beside it: mobility, loops and their assembly branches, Grashof classes,
transmission angles and health — each from the function ``vloop info`` and the teaching tables use."""

from __future__ import annotations

import math
from typing import Any

import numpy as np


def describe(mech: Any, system: Any, result: Any) -> dict[str, Any]:
    """Plain JSON-ready facts about a solved drawing (angles in degrees for reading)."""
    n_links, n_joints, mobility = mech.gruebler()
    return {
        "name": mech.name,
        "units": mech.units,
        "mobility": {"L": n_links, "J": n_joints, "M": mobility, "drivers": len(mech.drivers)},
        "loops": _loops(system),
        "grashof": _grashof(system),
        "transmission": _transmission(mech, system, result),
        "health": {k: float(np.max(v)) for k, v in result.health.items() if len(v) and np.all(np.isfinite(v))},
        "samples": len(result),
    }


def _loops(system: Any) -> list[dict[str, Any]]:
    """Each loop's label and, for a closed-form dyad, its branch at t = 0 (σ and the text ``vloop info`` prints:
    "open (B left of A→O4)", "E right of P→O6")."""
    from vloop.method.branches import dyad_branch

    out = [{"number": lp.index + 1, "label": lp.label, "branch": None, "sigma": None} for lp in system.loops]
    for b in system.blocks:
        if b.kind in ("RRR", "RRP", "RPR"):
            lp = system.loops[b.loops[0]]
            branch = dyad_branch(system, b, system.q0)
            out[lp.index].update(branch=branch.text() if branch else None, sigma=float(b.sigma))
    return out


def _grashof(system: Any) -> list[dict[str, Any]]:
    from vloop.method.equations import grashof

    return [{"loop": li + 1, "class": cls, "lengths": [float(v) for v in dims]} for li, cls, dims in grashof(system)]


def _transmission(mech: Any, system: Any, result: Any) -> list[dict[str, Any]]:
    """Each dyad's transmission angle folded to [0°, 90°]: its least and largest over the displayed samples."""
    from vloop.teaching import transmission_angles

    out = []
    for ta in transmission_angles(mech, result, system):
        folded = ta.folded
        if not len(folded) or not np.all(np.isfinite(folded)):
            continue
        k = int(np.argmin(folded))
        out.append({
            "dyad": ta.dyad.label, "min": math.degrees(float(folded[k])), "max": math.degrees(float(np.max(folded))),
            "at": float(result.t[k]),
        })  # fmt: skip
    return out
