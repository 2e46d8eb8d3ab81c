"""The linkages synthesis proposes, as mechanism files: which joints they have, how they are linked, which link
is driven, which body is guided and which point traces the path.

A linkage here is described by the world coordinates of its joints (and tracer point) at t = 0. Any set of
coordinates is a closed assembly (every loop vector is a difference of two of them), so a synthesized linkage
needs no assembly step: its coordinates go into the file as they are. The assembly branch is the one the
coordinates show: for each RRR dyad (``Topology.dyads``: known end, middle pin, known end) the side of the
line through its ends that the middle pin is on.

Topologies: the four-bar (ground O2–O4, crank O2A, coupler AB carrying tracer P, rocker O4B), the Stephenson
III six-bar (that four-bar with a dyad C–D–O6 hung on coupler point C, tracer P on link CD) and the offset
slider-crank (crank O2A, rod AB, slider at B along +x).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..files.fileformat import from_dict, to_dict
from ..model import Mechanism


@dataclass(frozen=True)
class Topology:
    """A linkage type: its joints and points (``coordinates``, in gene order), its [links] table, the driven
    link, the guided body, the tracer point, the RRR dyads in solving order, and a nominal member (closed
    t = 0 coordinates of a healthy linkage of this type, size about 1)."""

    name: str
    coordinates: tuple[str, ...]
    links: dict[str, tuple[str, ...]]
    ground: str
    input: str
    pivot: str
    guided: str
    tracer: str | None
    dyads: tuple[tuple[str, str, str], ...]
    nominal: dict[str, complex]
    sliders: dict[str, tuple[str, tuple[float, float]]] | None = None

    @property
    def points(self) -> dict[str, str]:
        """Tracer points (not joints of any link) and the body carrying them."""
        return {self.tracer: self.guided} if self.tracer else {}

    def mechanism(
        self,
        coords: dict[str, complex],
        *,
        name: str,
        omega: float,
        times: np.ndarray,
        units: str = "m",
        title: str = "",
    ) -> Mechanism:
        """The mechanism with these t = 0 coordinates (closed as they are), its input turning at ``omega``
        [rad/s] from the coordinates' angle, sampled at ``times`` [s]."""
        return from_dict(self.file(coords, name=name, omega=omega, times=times, units=units, title=title))

    def file(
        self, coords: dict[str, complex], *, name: str, omega: float, times: np.ndarray, units: str, title: str
    ) -> dict[str, Any]:
        """The mechanism file's TOML structure (see :meth:`mechanism`)."""
        pts = self.points
        joints = {j: [float(coords[j].real), float(coords[j].imag)] for j in self.coordinates if j not in pts}
        out: dict[str, Any] = {"name": name, "units": units}
        if title:
            out["title"] = title
        out["joints"] = joints
        out["links"] = {
            n: ({"joints": list(js), "ground": True} if n == self.ground else {"joints": list(js)})
            for n, js in self.links.items()
        }
        if self.sliders:
            out["sliders"] = {
                n: {"joint": j, "guide": self.ground, "axis": list(axis)} for n, (j, axis) in self.sliders.items()
            }
        present = {p: body for p, body in pts.items() if p in coords}
        if present:
            out["points"] = {p: {"link": body, "at": [coords[p].real, coords[p].imag]} for p, body in present.items()}
        out["drivers"] = [{"link": self.input, "pivot": self.pivot, "omega": float(omega)}]
        out["time"] = {"times": [float(t) for t in times]}
        return out

    def without_tracer(self) -> Topology:
        """The same linkage with no tracer point (a function generator)."""
        return Topology(
            self.name,
            tuple(c for c in self.coordinates if c != self.tracer),
            self.links,
            self.ground,
            self.input,
            self.pivot,
            self.guided,
            None,
            self.dyads,
            {k: v for k, v in self.nominal.items() if k != self.tracer},
            self.sliders,
        )


FOURBAR = Topology(
    "fourbar",
    ("O2", "A", "B", "O4", "P"),
    {"ground": ("O2", "O4"), "crank": ("O2", "A"), "coupler": ("A", "B"), "rocker": ("O4", "B")},
    "ground",
    "crank",
    "O2",
    "coupler",
    "P",
    (("A", "B", "O4"),),
    # a crank-rocker: a = 0.3, b = 1, c = 0.8, d = 1, crank at 60°, B above the diagonal A–O4
    {"O2": 0j, "A": 0.15 + 0.2598076211353316j, "B": 0.9915700673773525 + 0.7999555839144932j, "O4": 1 + 0j,
     "P": 0.5 + 0.8j},
)  # fmt: skip

STEPHENSON3 = Topology(
    "stephenson3",
    ("O2", "A", "B", "O4", "C", "D", "O6", "P"),
    {
        "ground": ("O2", "O4", "O6"),
        "crank": ("O2", "A"),
        "coupler": ("A", "B", "C"),
        "rocker": ("O4", "B"),
        "link5": ("C", "D"),
        "link6": ("O6", "D"),
    },
    "ground",
    "crank",
    "O2",
    "link5",
    "P",
    (("A", "B", "O4"), ("C", "D", "O6")),
    # the catalog's Stephenson III (mechanisms/sixbar_stephenson3.toml) scaled by 1/5, tracer on link CD
    {"O2": 0j, "A": 0.3464101615137755 + 0.2j, "B": 1.0626891205249124 + 0.897814053224727j, "O4": 1 + 0j,
     "C": 0.49520542505192573 + 0.7637907143157046j, "D": 0.5559720742988445 + 1.6617369344977944j,
     "O6": -0.2 + 1.4j, "P": 0.4 + 1.2j},
)  # fmt: skip

SLIDER_CRANK = Topology(
    "slider-crank",
    ("O2", "A", "B"),
    {"ground": ("O2",), "crank": ("O2", "A"), "rod": ("A", "B")},
    "ground",
    "crank",
    "O2",
    "rod",
    None,
    (),
    {"O2": 0j, "A": 0.3j, "B": 0.9539392014169457 + 0j},
    {"slider": ("B", (1.0, 0.0))},
)

TOPOLOGIES = {t.name: t for t in (FOURBAR, STEPHENSON3, SLIDER_CRANK)}


def side(coords: dict[str, np.ndarray], dyad: tuple[str, str, str]) -> np.ndarray:
    """+1 / −1: which side of the line from a dyad's first end to its second its middle pin is on (the
    assembly branch the coordinates show); arrays over variants."""
    e1, m, e2 = (np.asarray(coords[k]) for k in dyad)
    return np.where(((e2 - e1).conjugate() * (m - e1)).imag >= 0, 1.0, -1.0)


def reflect(z: complex, a: complex, b: complex) -> complex:
    """The mirror image of point ``z`` in the line through ``a`` and ``b``."""
    u = (b - a) / abs(b - a)
    return a + u * ((z - a) / u).conjugate()


def coordinates_at(mech: Mechanism, topology: Topology, t: float) -> dict[str, complex]:
    """Every joint's and point's world position at time ``t`` [s] of the mechanism's motion (vloop.solve)."""
    from .. import solve

    res = solve(mech, np.array([float(t)]))
    return {j: complex(res[f"{j}.x"][0], res[f"{j}.y"][0]) for j in topology.coordinates}


def reanchored(mech: Mechanism, topology: Topology, t: float, times: np.ndarray) -> Mechanism:
    """The same linkage with its t = 0 instant moved to time ``t`` of its motion: closed coordinates there (from
    vloop.solve), the same input speed, sampled at ``times`` [s] (measured from the new t = 0)."""
    data = to_dict(mech)
    coords = coordinates_at(mech, topology, t) if t != 0.0 else None
    if coords is not None:
        for j in data["joints"]:
            data["joints"][j] = [coords[j].real, coords[j].imag]
        for p in data.get("points", {}):
            data["points"][p]["at"] = [coords[p].real, coords[p].imag]
        data["drivers"][0].pop("theta0", None)  # the coordinates' angle: θ(t) of the old motion
    data["time"] = {"times": [float(x) for x in times]}
    return from_dict(data)


def lengths(mech: Mechanism) -> dict[str, float]:
    """Every binary link's length and every ternary link's sides, from the t = 0 coordinates [length]."""
    out = {}
    for name, lk in mech.links.items():
        js = lk.joints
        pairs = [(js[i], js[j]) for i in range(len(js)) for j in range(i + 1, len(js))]
        for a, b in pairs:
            (xa, ya), (xb, yb) = mech.joints[a], mech.joints[b]
            key = name if len(js) == 2 and not lk.ground else f"{name}.{a}{b}"
            out[key] = float(np.hypot(xb - xa, yb - ya))
    for p in mech.points.values():
        lk = mech.links.get(p.link)
        if lk is not None:
            for j in lk.joints:
                (xa, ya), (xb, yb) = mech.joints[j], p.at
                out[f"{p.link}.{j}{p.name}"] = float(np.hypot(xb - xa, yb - ya))
    return out
