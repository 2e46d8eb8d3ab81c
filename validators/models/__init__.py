"""The mechanism as a model for other engines: ``vloop export FILE --format mjcf|exudyn|pinocchio``.

    from validators.models import export
    export(mech, "out/fourbar", "mjcf")        # out/fourbar/<name>.xml: MuJoCo, with its t = 0 keyframe
    export(mech, "out/fourbar", "pinocchio")   # out/fourbar/<name>_pinocchio.py: run it, it writes a CSV
    export(mech, "out/fourbar", "exudyn")      # out/fourbar/<name>_exudyn.py

One construction per engine, shared with the validators that run it: the MJCF is what the ``mujoco`` engine
simulates (:mod:`validators.models.mjcf`, :mod:`validators.mujoco`); the scripts carry the Pinocchio and Exudyn
engines' own model-building code (:mod:`validators.models.scripts`). docs/elsewhere.md says what each model
represents and what it does not.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from vloop.errors import VloopError
from vloop.mechanism import Mechanism

FORMATS = ("mjcf", "exudyn", "pinocchio")
NEEDS = {"mjcf": ("mujoco", "mujoco"), "exudyn": ("exudyn", "exudyn"), "pinocchio": ("pinocchio", "pin")}


def export(mech: Mechanism, folder: str | Path, fmt: str, source: str = "") -> Path:
    """Write ``mech``'s model for ``fmt`` into ``folder`` (an OutputSet's stage from the CLI); returns its path.
    ``source``: where the mechanism came from (named in the script's header)."""
    from .scripts import check, exudyn_script, pinocchio_script

    if fmt not in FORMATS:
        raise VloopError(f"{mech.name}: --format {fmt!r}: one of {', '.join(FORMATS)}", entry="format")
    from vloop.files.output import safe_folder_name

    stem = safe_folder_name(mech.name)
    folder = Path(folder)
    if fmt == "mjcf":
        path = folder / f"{stem}.xml"
        path.write_text(mjcf_text(mech), encoding="utf-8")
        return path
    path = folder / f"{stem}_{fmt}.py"
    src = source or f"{mech.name} (vloop)"
    text = (pinocchio_script if fmt == "pinocchio" else exudyn_script)(mech, path.name, src)
    check(text)
    path.write_text(text, encoding="utf-8")
    return path


def mjcf_text(mech: Mechanism) -> str:
    """The MJCF of ``mech`` with the keyframe ``t0``: the assembly at t = 0 (MuJoCo's own, :func:`mujoco.assemble`),
    consistent rates, the servos' set points and ctrl (the input's speed; the loads' values)."""
    import mujoco as mj

    from .. import mujoco as engine
    from .mjcf import build

    engine.quiet()
    text, layout = build(mech)
    model = mj.MjModel.from_xml_string(text)
    data = mj.MjData(model)
    engine.assemble(model, data, layout, mech, 0.0)
    ctrl = list(data.ctrl)
    for i, value in enumerate(_load_ctrl(mech)):
        ctrl[2 * len(mech.drivers) + i] = value
    key = (
        f'  <keyframe>\n    <key name="t0" time="0" qpos="{_list(data.qpos)}" qvel="{_list(data.qvel)}"'
        + (f' act="{_list(data.act)}"' if model.na else "")
        + (f' ctrl="{_list(ctrl)}"' if model.nu else "")
        + "/>\n  </keyframe>\n"
    )
    return text.replace("</mujoco>", key + "</mujoco>")


def _load_ctrl(mech: Mechanism) -> list[float]:
    """The loads' actuators' ctrl at t = 0: 1 for a constant load (its value is the gear), a table's first row."""
    import numpy as np

    out: list[float] = []
    for ld in mech.loads:
        if ld.profile is None:
            out.append(1.0)
        else:
            row = [
                float(np.interp(0.0, ld.profile.t, ld.profile.values[:, c])) for c in range(ld.profile.values.shape[1])
            ]
            out += row if ld.kind == "force" else row[:1]
    return out


def _list(values: Any) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)
