"""Variants of a mechanism that differ from it only in numbers, as arrays over variants.

A design study varies numbers of a mechanism file, never its topology, so every variant shares the
nominal LoopSystem's structure (graph, loops, blocks, unknowns). What varies, per variant, is:

* the vector terms' constants r and δ (from joint and point coordinates, stated lengths of binary
  links, slider axes and the offsets of their sliding lines), exactly as :mod:`vloop.method.graph` derives
  them from a file, but vectorized over variants;
* the drivers' numbers x0, v0, a0 (theta0/omega/alpha of a crank, s0/v/a of an actuator);
* the frame offsets of slider blocks (their θ output) and the starting guess of the t = 0 assembly.

Parameter names follow the file: ``joints.B.x``, ``points.C.y``, ``links.l3.length`` (a binary moving
link), ``sliders.s1.angle`` (axis direction [rad]), ``sliders.s1.offset`` (signed distance of the
sliding line from the guide's origin, to the left of the axis [length]), ``drivers.l2.theta0 | omega |
alpha`` (a crank, named by its link) and ``drivers.s1.s0 | v | a`` (an actuator, named by its slider).
A driver's x0 keeps its offset from the coordinates when they move (as a file without theta0/s0 does),
unless it is a parameter itself.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from ..errors import MechanismError
from ..method.graph import loop_row
from ..method.loops import LoopSystem
from ..model import Driver, Link, Mechanism, Point, Slider, third_corner

TWO_PI = 2.0 * math.pi
FD_STEP = 6e-6  # central-difference step, relative to a parameter's typical size (≈ ε^(1/3))

# field → (unit kind, what it is) for each section
FIELDS = {
    "joints": {"x": "length", "y": "length"},
    "points": {"x": "length", "y": "length"},
    "links": {"length": "length"},
    "sliders": {"angle": "rad", "offset": "length"},
    "crank": {"theta0": "rad", "omega": "rad/s", "alpha": "rad/s²"},
    "actuator": {"s0": "length", "v": "length/s", "a": "length/s²"},
}


@dataclass(frozen=True)
class ParamRef:
    """One varied number: its name, where it lives in the file, its unit and nominal value, and the typical
    size a central-difference step is taken relative to."""

    name: str
    section: str  # joints | points | links | sliders | drivers
    target: str  # the joint, point, link, slider or driven link/slider
    field: str
    unit: str
    nominal: float
    typical: float

    @property
    def positive(self) -> bool:
        """Whether the value must be positive (a link length)."""
        return self.section == "links"

    def fd_step(self) -> float:
        """The central-difference step [the parameter's unit]."""
        return FD_STEP * max(abs(self.nominal), self.typical)


def resolve(mech: Mechanism, name: object, entry: str) -> ParamRef:
    """The parameter a name refers to; MechanismError naming ``entry`` if the name refers to nothing variable."""
    if not isinstance(name, str) or name.count(".") != 2:
        raise MechanismError(
            f"[{entry}] name must be SECTION.ENTRY.FIELD (e.g. links.l3.length, joints.B.x, drivers.l2.omega), "
            f"got {_show(name)}",
            entry=entry,
        )
    section, target, fld = name.split(".")
    if section not in ("joints", "points", "links", "sliders", "drivers"):
        raise MechanismError(
            f"[{entry}] {_show(name)}: the section must be one of joints, points, links, sliders, drivers",
            entry=entry,
        )
    ref = _RESOLVERS[section](mech, name, target, fld, entry)
    return dataclasses.replace(ref, unit=ref.unit.replace("length", mech.units))


def _resolve_joint(mech: Mechanism, name: str, target: str, fld: str, entry: str) -> ParamRef:
    table = mech.joints if name.startswith("joints") else {p.name: p.at for p in mech.points.values()}
    section = name.split(".")[0]
    if target not in table:
        raise MechanismError(f"[{entry}] {name}: no {section[:-1]} {_show(target)} ({_known(table)})", entry=entry)
    _check_field(name, section, fld, entry)
    return ParamRef(name, section, target, fld, "length", table[target]["xy".index(fld)], mech.scale)


def _resolve_link(mech: Mechanism, name: str, target: str, fld: str, entry: str) -> ParamRef:
    if target not in mech.links:
        raise MechanismError(f"[{entry}] {name}: no link {_show(target)} ({_known(mech.links)})", entry=entry)
    _check_field(name, "links", fld, entry)
    lk = mech.links[target]
    if lk.ground:
        raise MechanismError(
            f"[{entry}] {name}: the ground's dimensions are its joints' coordinates: vary those (e.g. "
            f"joints.{lk.joints[-1]}.x)",
            entry=entry,
        )
    if len(lk.joints) != 2:
        raise MechanismError(
            f"[{entry}] {name}: a length is only for binary links (two joints); '{target}' has "
            f"{len(lk.joints)}: vary its joints' coordinates",
            entry=entry,
        )
    nominal = lk.length if lk.length is not None else math.dist(mech.joints[lk.joints[0]], mech.joints[lk.joints[1]])
    return ParamRef(name, "links", target, fld, "length", nominal, mech.scale)


def _resolve_slider(mech: Mechanism, name: str, target: str, fld: str, entry: str) -> ParamRef:
    if target not in mech.sliders:
        raise MechanismError(f"[{entry}] {name}: no slider {_show(target)} ({_known(mech.sliders)})", entry=entry)
    _check_field(name, "sliders", fld, entry)
    sl = mech.sliders[target]
    if fld == "angle":  # a stated angle is in the guide's frame; else the axis direction at t = 0
        nominal = sl.angle if sl.angle is not None else math.atan2(sl.axis[1], sl.axis[0])
        return ParamRef(name, "sliders", target, fld, "rad", nominal, 1.0)
    offset = sl.offset if sl.offset is not None else _nominal_offset(mech, sl)
    return ParamRef(name, "sliders", target, fld, "length", offset, mech.scale)


def _resolve_driver(mech: Mechanism, name: str, target: str, fld: str, entry: str) -> ParamRef:
    drv = next((d for d in mech.drivers if d.target == target), None)
    if drv is None:
        names = ", ".join(d.target for d in mech.drivers)
        raise MechanismError(f"[{entry}] {name}: no driver of {_show(target)} (drivers: {names})", entry=entry)
    kind = "crank" if drv.kind == "crank" else "actuator"
    _check_field(name, kind, fld, entry)
    if drv.profile is not None:
        raise MechanismError(
            f"[{entry}] {name}: the driver of '{target}' follows a profile; only a driver given by its numbers "
            "(theta0/omega/alpha or s0/v/a) can vary",
            entry=entry,
        )
    i = ("theta0", "omega", "alpha", "s0", "v", "a").index(fld) % 3
    value = (drv.x0, drv.v0, drv.a0)[i]
    unit = FIELDS[kind][fld].replace("length", mech.units)
    typical = 1.0 if drv.kind == "crank" else mech.scale
    return ParamRef(name, "drivers", target, fld, unit, value, typical)


_RESOLVERS = {
    "joints": _resolve_joint,
    "points": _resolve_joint,
    "links": _resolve_link,
    "sliders": _resolve_slider,
    "drivers": _resolve_driver,
}


def _check_field(name: str, section: str, fld: str, entry: str) -> None:
    if fld not in FIELDS[section]:
        what = {"crank": "a crank driver", "actuator": "an actuator"}.get(section, section)
        raise MechanismError(
            f"[{entry}] {name}: {what} has no variable field {_show(fld)} (fields: {', '.join(FIELDS[section])})",
            entry=entry,
        )


def _show(value: object) -> str:
    from ..files.schema import show

    return show(value, 40)


def _known(table: dict) -> str:
    names = list(table)
    return f"known: {', '.join(names[:12])}{', ...' if len(names) > 12 else ''}" if names else "there are none"


def _nominal_offset(mech: Mechanism, sl: Slider) -> float:
    """The sliding line's signed distance from the guide's origin (left of the axis positive), as the graph
    computes its offset term at t = 0."""
    g = mech.bodies()[sl.guide]
    dx, dy = mech.joints[sl.joint][0] - g.origin[0], mech.joints[sl.joint][1] - g.origin[1]
    cg, sg = math.cos(g.theta0), math.sin(g.theta0)
    lx, ly = cg * dx + sg * dy, -sg * dx + cg * dy
    alpha = math.atan2(sl.axis[1], sl.axis[0]) - g.theta0
    return -lx * math.sin(alpha) + ly * math.cos(alpha)


# ---------------------------------------------------------------- the numbers of many variants


@dataclass
class Designs:
    """Per-variant numbers on a shared LoopSystem (V variants; arrays over variants first).

    ``r``, ``delta``, ``cd`` (V, n_terms): term magnitudes, angle offsets and e^{jδ}; ``x0``, ``v0``, ``a0``
    (V, n_drivers): driver numbers; ``q_start`` (V, n_vars): the t = 0 assembly's starting guess (the nominal
    assembly moved as the coordinates moved); ``out_offset`` (V, n_link_outputs): the θ offset of each output
    body (slider blocks: their axis from their guide's frame); ``coords_q`` (V, n_vars): the variables the
    coordinates give.
    """

    r: np.ndarray
    delta: np.ndarray
    cd: np.ndarray
    x0: np.ndarray
    v0: np.ndarray
    a0: np.ndarray
    q_start: np.ndarray
    out_offset: np.ndarray
    coords_q: np.ndarray

    def __len__(self) -> int:
        return len(self.r)

    def take(self, rows: np.ndarray | slice) -> Designs:
        """The designs of some variants."""
        return Designs(**{f.name: getattr(self, f.name)[rows] for f in dataclasses.fields(self)})

    def blend(self, other: Designs, lam: float) -> Designs:
        """The designs a fraction ``lam`` of the way from ``self`` (one nominal row, broadcast) to ``other``:
        term vectors and driver numbers blended linearly (the continuation of the t = 0 assembly)."""
        c = (1.0 - lam) * self.cd + lam * other.cd
        cd = c / np.where(np.abs(c) > 0, np.abs(c), 1.0)
        r = (1.0 - lam) * self.r + lam * other.r
        x0 = (1.0 - lam) * self.x0 + lam * other.x0
        shape = other.r.shape
        return dataclasses.replace(
            other,
            r=np.broadcast_to(r, shape).copy(),
            cd=np.broadcast_to(cd, shape).copy(),
            x0=x0,
            delta=np.angle(np.broadcast_to(cd, shape)) % TWO_PI,
        )


@dataclass
class VariantModel:
    """Everything needed to turn parameter values into :class:`Designs` for one nominal mechanism.

    ``system`` is the nominal LoopSystem (with a zero-length offset term added for a slider whose offset
    varies but is zero in the file: the structure then has room for it).
    """

    mechanism: Mechanism
    system: LoopSystem
    params: tuple[ParamRef, ...]
    roles: list[tuple] = field(default_factory=list, repr=False)

    @classmethod
    def build(cls, mech: Mechanism, system: LoopSystem, params: tuple[ParamRef, ...]) -> VariantModel:
        system = _with_offset_terms(mech, _with_zero_terms(system), params)
        model = cls(mech, system, params, _term_roles(mech, system))
        model._check_nominal()
        return model

    def nominal_values(self) -> np.ndarray:
        return np.array([p.nominal for p in self.params], float)

    def designs(self, values: np.ndarray) -> Designs:
        """The designs of variants whose parameter values are the rows of ``values`` (V, n_params)."""
        values = np.atleast_2d(np.asarray(values, float))
        geo = _Geometry(self, values)
        r, delta = geo.terms()
        coords_q = geo.coords_q()
        system = self.system
        nom = _Geometry(self, self.nominal_values()[None, :])
        dq = coords_q - nom.coords_q()
        na = system.n_angles
        dq[:, :na] = np.angle(np.exp(1j * dq[:, :na]))  # a coordinate angle that wraps past 2π moves by a little
        x0, v0, a0 = self._drivers(values, dq)
        q_start = system.q0[None, :] + dq
        for j, v in enumerate(system.drivers):
            q_start[:, v] = x0[:, j]
        return Designs(r, delta, np.exp(1j * delta), x0, v0, a0, q_start, geo.out_offsets(), coords_q)

    def _drivers(self, values: np.ndarray, dq: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        system, mech = self.system, self.mechanism
        V = len(values)
        nums = [np.tile([d.x0, d.v0, d.a0], (V, 1)).astype(float) for d in mech.drivers]
        for j, v in enumerate(system.drivers):
            nums[j][:, 0] += dq[:, v]  # x0 keeps its offset from the coordinates
        for k, p in enumerate(self.params):
            if p.section == "drivers":
                j = next(i for i, d in enumerate(mech.drivers) if d.target == p.target)
                nums[j][:, ("theta0", "omega", "alpha", "s0", "v", "a").index(p.field) % 3] = values[:, k]
        m = len(mech.drivers)
        stack = np.stack(nums, axis=1) if m else np.zeros((V, 0, 3))
        return stack[:, :, 0], stack[:, :, 1], stack[:, :, 2]

    def _check_nominal(self) -> None:
        """The nominal values must give back the compiled constants (guards this module against the graph's)."""
        d = self.designs(self.nominal_values()[None, :])
        system = self.system
        scale = self.mechanism.scale
        dz = np.abs(d.r[0] * d.cd[0] - system.t_r * np.exp(1j * system.t_delta))
        if np.any(dz > 1e-9 * scale) or np.any(np.abs(d.x0[0] - [x.x0 for x in self.mechanism.drivers]) > 1e-12):
            raise RuntimeError("vloop.core.variants does not reproduce the compiled vector terms (graph changed?)")

    def variant_mechanism(
        self, values: np.ndarray, positions: dict[str, complex] | None = None, q0: np.ndarray | None = None
    ) -> Mechanism:
        """The variant as a Mechanism of its own: the file with these numbers (one row of values).

        With ``positions`` (every joint and point at the variant's t = 0 assembly) and ``q0`` (its assembled
        variables) the coordinates are the assembly's, so the file closes its loops exactly and loads anywhere
        (a slider's axis on a moving guide turns as its guide turned in the assembly); otherwise the edited
        coordinates as given (which close only approximately when a length or a driver's x0 changed)."""
        mech = self.mechanism
        values = np.asarray(values, float)
        joints, points = dict(mech.joints), dict(mech.points)
        links, sliders = dict(mech.links), dict(mech.sliders)
        for p, x in zip(self.params, values, strict=True):
            x = float(x)
            if p.section == "joints":
                xy = list(joints[p.target])
                xy["xy".index(p.field)] = x
                joints[p.target] = (xy[0], xy[1])
            elif p.section == "points":
                at = list(points[p.target].at)
                at["xy".index(p.field)] = x
                points[p.target] = dataclasses.replace(points[p.target], at=(at[0], at[1]))
            elif p.section == "links":
                links[p.target] = dataclasses.replace(links[p.target], length=x)
            elif p.section == "sliders":
                sliders[p.target] = _varied_slider(sliders[p.target], p.field, x)
        d = self.designs(values[None, :])
        if positions is not None:
            joints = {j: (positions[j].real, positions[j].imag) for j in joints}
            points = {n: dataclasses.replace(pt, at=(positions[n].real, positions[n].imag)) for n, pt in points.items()}
            if q0 is not None:
                sliders = {n: self._turned_axis(sl, d, q0) for n, sl in sliders.items()}
        drivers = tuple(
            dataclasses.replace(drv, x0=float(d.x0[0, j]), v0=float(d.v0[0, j]), a0=float(d.a0[0, j]))
            for j, drv in enumerate(mech.drivers)
        )
        out = dataclasses.replace(mech, joints=joints, points=points, links=links, sliders=sliders, drivers=drivers)
        out.__dict__.pop("scale", None)  # a cached property of the nominal
        return out

    def _turned_axis(self, sl: Slider, d: Designs, q0: np.ndarray) -> Slider:
        """A slider's t = 0 axis at the variant's assembly ``q0`` (a guide that moves turns it)."""
        if sl.angle is not None:  # stated in the guide's frame: the axis is the guide's θ at the assembly plus it
            th = sl.angle + (
                float(q0[self.system.angle_links.index(sl.guide)]) if sl.guide in self.system.angle_links else 0.0
            )
            return dataclasses.replace(sl, axis=(math.cos(th), math.sin(th)))
        return self._turned_world_axis(sl, d, q0)

    def _turned_world_axis(self, sl: Slider, d: Designs, q0: np.ndarray) -> Slider:
        """A slider on a moving guide: its world axis turned as the guide turned from its coordinates to the
        assembly (the axis is fixed to the guide)."""
        system = self.system
        if sl.guide not in system.angle_links:
            return sl
        a = system.angle_links.index(sl.guide)
        turn = float(q0[a] - d.coords_q[0, a])
        c, s = math.cos(turn), math.sin(turn)
        return dataclasses.replace(sl, axis=(c * sl.axis[0] - s * sl.axis[1], s * sl.axis[0] + c * sl.axis[1]))


# ---------------------------------------------------------------- geometry of many variants


class _Geometry:
    """Body frames and local coordinates of every variant (the vectorized :func:`vloop.model._bodies` and
    :func:`vloop.method.graph.build_graph` terms)."""

    def __init__(self, model: VariantModel, values: np.ndarray) -> None:
        self.model = model
        mech = model.mechanism
        V = len(values)
        self.V = V
        self.P = {j: np.full(V, complex(*xy)) for j, xy in mech.joints.items()}
        self.P.update({n: np.full(V, complex(*pt.at)) for n, pt in mech.points.items()})
        self.length = {n: _stated_length(lk, V) for n, lk in mech.links.items()}
        self.axis = {n: np.full(V, math.atan2(s.axis[1], s.axis[0])) for n, s in mech.sliders.items()}
        self.angle = {n: np.full(V, s.angle) for n, s in mech.sliders.items() if s.angle is not None}  # guide frame
        self.offset = {n: np.full(V, s.offset) for n, s in mech.sliders.items() if s.offset is not None}
        for k, p in enumerate(model.params):
            x = values[:, k]
            if p.section in ("joints", "points"):
                self.P[p.target] = self.P[p.target].real + 1j * x if p.field == "y" else x + 1j * self.P[p.target].imag
            elif p.section == "links":
                self.length[p.target] = x.copy()
            elif p.section == "sliders":
                stated = self.angle if p.target in self.angle else self.axis
                (stated if p.field == "angle" else self.offset)[p.target] = x.copy()
        self.frames = {b: self._frame(b) for b in mech.body_names}

    def _frame(self, body: str) -> tuple[np.ndarray, np.ndarray]:
        """(origin, θ0) of a body's frame per variant (θ0 in [0, 2π), as the model gives it)."""
        mech = self.model.mechanism
        if body == mech.ground:
            return np.zeros(self.V, complex), np.zeros(self.V)
        if body in mech.sliders:
            sl = mech.sliders[body]
            if body in self.angle:  # turned with its guide (a one-joint guide never states an angle)
                return self.P[sl.joint], (self._frame(sl.guide)[1] + self.angle[body]) % TWO_PI
            return self.P[sl.joint], self.axis[body] % TWO_PI
        lk = mech.links[body]
        o = self.P[lk.joints[0]]
        if len(lk.joints) >= 2:
            d = self.P[lk.joints[1]] - o
            return o, np.arctan2(d.imag, d.real) % TWO_PI
        guided = next(s for s in mech.sliders.values() if s.guide == body)
        return o, self.axis[guided.name] % TWO_PI

    def local(self, body: str, member: str) -> np.ndarray:
        """A member's coordinates in its body's frame (complex), as Body.local gives them."""
        mech = self.model.mechanism
        if member in mech.points and mech.points[member].local is not None:
            return np.full(self.V, complex(*mech.points[member].local))
        if body == mech.ground:
            return self.P[member]
        o, th = self.frames[body]
        lk = mech.links.get(body)
        if lk is not None and len(lk.joints) >= 2 and member == lk.joints[1]:
            stated = self.length[body]
            return (stated if stated is not None else np.abs(self.P[member] - o)) + 0j
        if lk is not None and lk.sides is not None and member == lk.joints[2]:
            return self._third_corner(lk)
        c, s = np.cos(th), np.sin(th)
        d = self.P[member] - o
        return (c * d.real + s * d.imag) + 1j * (-s * d.real + c * d.imag)

    def _third_corner(self, lk: Link) -> np.ndarray:
        """J2 of a ternary link stated by its sides, in its frame (:func:`vloop.model.third_corner` per variant: three
        sides on the side of J0→J1 where each variant's coordinates draw J2)."""
        x, y = third_corner(lk, [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0)])  # two sides: the angle fixes it
        if len(lk.sides or ()) == 2:
            return np.full(self.V, complex(x, y))
        p0, p1, p2 = (self.P[j] for j in lk.joints)
        turn = ((p1 - p0).conjugate() * (p2 - p0)).imag
        return x + 1j * np.where(turn >= 0, y, -y)

    def frame_offset(self, body: str) -> np.ndarray:
        """The constant angle of a body's frame from the angle variable that turns it (blocks: axis − guide)."""
        mech = self.model.mechanism
        if body not in mech.sliders:
            return np.zeros(self.V)
        return self.frames[body][1] - self.frames[mech.sliders[body].guide][1]

    def slider_line(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(α, s0, e) of slider i: axis angle in its guide's frame, the joint's s and the line's offset."""
        mech = self.model.mechanism
        sl = list(mech.sliders.values())[i]
        o, th = self.frames[sl.guide]
        d = self.P[sl.joint] - o
        cg, sg = np.cos(th), np.sin(th)
        lx, ly = cg * d.real + sg * d.imag, -sg * d.real + cg * d.imag
        alpha = self.angle[sl.name] if sl.name in self.angle else self.axis[sl.name] - th
        s0 = lx * np.cos(alpha) + ly * np.sin(alpha)
        e = self.offset.get(sl.name, -lx * np.sin(alpha) + ly * np.cos(alpha))
        return alpha, s0, e

    def terms(self) -> tuple[np.ndarray, np.ndarray]:
        """(r, δ) of every term for every variant (V, n_terms), δ in [0, 2π)."""
        nt = len(self.model.system.t_r)
        r = np.zeros((self.V, nt))
        delta = np.zeros((self.V, nt))
        lines = {}
        for t, role in enumerate(self.model.roles):
            if role[0] == "chord":  # after its parts (chords are added to the terms last)
                z = sum(c * r[:, p] * np.exp(1j * delta[:, p]) for p, c in role[1])
                r[:, t], delta[:, t] = np.abs(z), np.angle(z)
                continue
            if role[0] == "body":
                loc = self.local(role[1], role[2])
                r[:, t] = np.hypot(loc.real, loc.imag)
                delta[:, t] = np.arctan2(loc.imag, loc.real) + self.frame_offset(role[1])
                continue
            i = role[1]
            if i not in lines:
                lines[i] = self.slider_line(i)
            alpha, _, e = lines[i]
            if role[0] == "slider":
                delta[:, t] = alpha
            else:  # the sliding line's offset: e·e^{j(α + π/2)}, kept as a positive magnitude
                r[:, t] = np.abs(e)
                delta[:, t] = alpha + math.pi / 2 + np.where(e < 0, math.pi, 0.0)
        return r, delta % TWO_PI

    def coords_q(self) -> np.ndarray:
        """The variables the coordinates give: every rotating link's θ0, every slider's s0."""
        system = self.model.system
        q = [self.frames[n][1] for n in system.angle_links]
        q += [self.slider_line(i)[1] for i in range(len(system.slider_names))]
        return np.stack(q, axis=1) if q else np.zeros((self.V, 0))

    def out_offsets(self) -> np.ndarray:
        """The θ offset of every output body (links: 0; blocks: axis − guide)."""
        system = self.model.system
        cols = [self.frame_offset(name) for name, _, _ in system.link_outputs]
        return np.stack(cols, axis=1) if cols else np.zeros((self.V, 0))


def _stated_length(lk: Link, V: int) -> np.ndarray | None:
    """A link's stated distance from its first joint to its second (a length, or a ternary's first side)."""
    stated = lk.length if lk.length is not None else (lk.sides[0] if lk.sides else None)
    return None if stated is None else np.full(V, stated)


def _term_roles(mech: Mechanism, system: LoopSystem) -> list[tuple]:
    """What each term is: ("body", body, member), ("slider", i) or ("offset", i), read from the graph's edges, or
    ("chord", parts): a body's vectors that a loop crosses, summed (:func:`vloop.graph.crossings`)."""
    roles: list[tuple | None] = [None] * len(system.t_r)
    slider_index = {n: i for i, n in enumerate(mech.sliders)}
    for u, v, data in system.graph.edges(data=True):
        kind = data.get("kind")
        if kind == "link":
            node = v if data["start"] == u else u
            roles[data["terms"][0][0]] = ("body", node[0], node[1])
        elif kind == "slider":
            block = u[0] if u[0] in mech.sliders else v[0]
            i = slider_index[block]
            for tid, _ in data["terms"]:
                roles[tid] = ("slider", i) if system.t_sl[tid] >= 0 else ("offset", i)
    for t, extra in system.cache.get("study_offset_terms", {}).items():
        roles[t] = ("offset", extra)
    for t, parts in system.chords:
        roles[t] = ("chord", parts)
    if any(r is None for r in roles):
        raise RuntimeError("vloop.core.variants cannot tell what every vector term is (graph changed?)")
    return roles  # type: ignore[return-value]


def _with_zero_terms(system: LoopSystem) -> LoopSystem:
    """The loops' coefficients of vectors of zero length restored (the compiler drops them: a ground joint at the
    world origin adds nothing), so a variant that moves such a joint off the origin keeps its vector. Only
    vectors fixed to the ground are zero-length in a loop (joints on one link never coincide), so the loops'
    variables do not change."""
    C = np.zeros_like(system.C)
    for li, lp in enumerate(system.loops):
        for tid, c, _ in loop_row(system.graph.adj, list(lp.nodes)):
            C[li, tid] += c
    for t, parts in system.chords:  # a chord stands for its parts in the loops that cross its body that way
        for li in np.flatnonzero(system.C[:, t]):
            for p, c in parts:
                C[li, p] -= system.C[li, t] * c
            C[li, t] += system.C[li, t]
    restored = (C != system.C) & (system.t_r == 0) & (system.t_sl < 0) & (system.t_ang < 0)
    if not restored.any():
        return system
    if np.any((C != system.C) & ~restored):
        raise RuntimeError("vloop.core.variants cannot rebuild the loop coefficients (graph changed?)")
    return dataclasses.replace(system, C=np.where(restored, C, system.C), cache={})


def _with_offset_terms(mech: Mechanism, system: LoopSystem, params: tuple[ParamRef, ...]) -> LoopSystem:
    """A slider whose offset varies but whose file line passes through its guide's origin has no offset term:
    add one of zero length (same loops and points as the slider's own term), so variants have room for it."""
    names = list(mech.sliders)
    want = {names.index(p.target) for p in params if p.section == "sliders" and p.field == "offset"}
    have = {names.index(s) for s in mech.sliders if any("offset of " + s == lbl for lbl in system.t_label)}
    missing = sorted(want - have)
    if not missing:
        return system
    t_ang, t_sl, t_r, t_delta = list(system.t_ang), list(system.t_sl), list(system.t_r), list(system.t_delta)
    C, path, labels = system.C.copy(), system.path.copy(), list(system.t_label)
    extra = {}
    for i in missing:
        ts = int(np.nonzero(system.t_sl == i)[0][0])
        t_ang.append(system.t_ang[ts])
        t_sl.append(-1)
        t_r.append(0.0)
        t_delta.append((system.t_delta[ts] + math.pi / 2) % TWO_PI)
        labels.append(f"offset of {names[i]}")
        C = np.concatenate([C, C[:, ts : ts + 1]], axis=1)
        path = np.concatenate([path, path[ts : ts + 1]], axis=0)
        extra[len(t_r) - 1] = i
    out = dataclasses.replace(
        system,
        t_ang=np.array(t_ang, int),
        t_sl=np.array(t_sl, int),
        t_r=np.array(t_r),
        t_delta=np.array(t_delta),
        t_label=tuple(labels),
        C=C,
        path=path,
        cache={},
    )
    out.cache["study_offset_terms"] = extra
    return out


__all__ = ["Designs", "Driver", "Link", "ParamRef", "Point", "Slider", "VariantModel", "resolve"]


def _varied_slider(sl: Slider, fld: str, x: float) -> Slider:
    """A slider with its angle or offset varied: a stated one replaced, else the axis (the offset of a slider that
    states none is in its joint's coordinates)."""
    if fld == "offset":
        return dataclasses.replace(sl, offset=x) if sl.offset is not None else sl
    if sl.angle is not None:
        return dataclasses.replace(sl, angle=x)
    return dataclasses.replace(sl, axis=(math.cos(x), math.sin(x)))
