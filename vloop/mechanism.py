"""The mechanism description, as one import: the data (:mod:`vloop.model`) and its file format
(:mod:`vloop.files.fileformat`, with the schema in :mod:`vloop.files.schema`).

Conventions (docs/file-format.md): lengths in the file's units, angles in radians, CCW
positive from +x; joint coordinates describe t = 0; a link's θ runs from its first to its second
joint; a slider's s is measured along its axis from its guide's origin.
"""

from __future__ import annotations

from .files.fileformat import (
    BRANCH_CHOICES,
    CHANGE_POINT_CHOICES,
    COINCIDENT_TOL,
    MAX_SAMPLES,
    dumps,
    from_dict,
    load,
    loads,
    save,
    to_dict,
)
from .model import (
    LENGTH_UNITS,
    Body,
    Driver,
    Link,
    Load,
    LoadProfile,
    MassProperties,
    Mechanism,
    Point,
    Profile,
    Slider,
    angle_text,
    length_factor,
    mobility_message,
)

__all__ = [
    "BRANCH_CHOICES",
    "CHANGE_POINT_CHOICES",
    "COINCIDENT_TOL",
    "LENGTH_UNITS",
    "MAX_SAMPLES",
    "Body",
    "Driver",
    "Link",
    "Load",
    "LoadProfile",
    "MassProperties",
    "Mechanism",
    "Point",
    "Profile",
    "Slider",
    "angle_text",
    "dumps",
    "from_dict",
    "length_factor",
    "load",
    "loads",
    "mobility_message",
    "save",
    "to_dict",
]
