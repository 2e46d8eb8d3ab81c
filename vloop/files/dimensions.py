"""Files written from dimensions: which files they are, and where their joints sit until vloop assembles them.

A file is *written from dimensions* when nothing in it depends on where its coordinates draw a moving body:
every moving link has its ``length`` (binary) or ``sides`` (ternary), every slider its ``offset`` (and its
``angle`` in the guide's frame when the guide moves), every point on a moving body its ``local`` coordinates and
every centre of mass its ``com_local`` (or the default). Its coordinates, other than the ground's, are then
hints: they may be rough or missing, and :mod:`vloop.authoring` assembles t = 0 from the dimensions on the
branch nearest them. Here, before any solving, the reader

* decides whether a file is written from dimensions (:func:`dimension_mode`), refusing the keys that only such a
  file may use (a slider's ``offset`` or ``angle``, a missing coordinate) in any other;
* measures the mechanism by its dimensions and its ground pivots, never by its hints (:func:`dimension_size`),
  and refuses a number far outside that size, naming its key (:func:`check_proportions`);
* places joints without coordinates provisionally, link by link from the placed ones (:func:`place_joints`;
  the assembly replaces them, only the ground's coordinates are kept);
* turns slider angles into t = 0 axes and points' ``local`` into t = 0 positions (:func:`axes_from_angles`,
  :func:`points_from_local`), through the body frames the coordinates give.
"""

from __future__ import annotations

import dataclasses
import math

from ..model import Link, Mechanism, Point, Slider, third_corner, to_world
from .schema import FAR, SIZES, Problems, beyond_sizes, show

HANDEDNESS_TOL = 1e-9  # |J0J1 × J0J2| below this fraction of |J0J1|·|J0J2|: the drawn triangle shows no side


def missing_dimensions(
    links: dict[str, Link], sliders: dict[str, Slider], points: dict[str, Point], data: dict
) -> list[str]:
    """What keeps a file from being written from dimensions (empty: it is), one phrase each."""
    why: list[str] = []
    ground = next((n for n, lk in links.items() if lk.ground), None)
    one_joint = {n for n, lk in links.items() if len(lk.joints) == 1}
    for n, lk in links.items():
        if lk.ground or len(lk.joints) == 1 or lk.dimensioned:
            continue
        need = {2: "length", 3: "sides"}.get(len(lk.joints))
        why.append(f"links.{n} has no {need}" if need else f"links.{n} has {len(lk.joints)} joints (at most 3)")
    for n, sl in sliders.items():
        if sl.offset is None:
            why.append(f"sliders.{n} has no offset")
        if sl.angle is None and sl.guide != ground and sl.guide not in one_joint:
            why.append(f"sliders.{n} on the moving guide {sl.guide} has no angle")
    why += [f"points.{n} has no local" for n, p in points.items() if p.local is None and p.link != ground]
    for section in ("links", "sliders"):
        for n, table in (data.get(section) or {}).items():
            if isinstance(table, dict) and "com" in table:
                why.append(f"{section}.{n} gives com (use com_local)")
    return why


def dimension_mode(
    links: dict[str, Link], sliders: dict[str, Slider], points: dict[str, Point], data: dict, probs: Problems
) -> tuple[bool, str]:
    """Whether the file is written from dimensions, and if not, what it lacks (a phrase for messages). A slider's
    ``offset`` or ``angle`` (which only such a file may state) in any other file is refused, naming what lacks."""
    why = missing_dimensions(links, sliders, points, data)
    if not why:
        return True, ""
    lacks = f"{'; '.join(why[:3])}{' ...' if len(why) > 3 else ''}"
    uses = [(n, k) for n, s in sliders.items() for k in ("offset", "angle") if getattr(s, k) is not None]
    for n, key in uses[:4]:
        probs.add(
            f"sliders.{n}",
            f"'{key}' needs a file written from dimensions (every moving link its length or sides, every slider its "
            f"offset and, on a moving guide, its angle; points local, centres of mass com_local); here {lacks}",
        )
    return False, lacks


def dimension_list(m: Mechanism) -> list[tuple[float, str, str]]:
    """Every stated dimension as (size ≥ 0 [file units], entry, key): lengths, sides, slider offsets, points' local."""
    out = [(x, f"links.{n}", "length") for n, lk in m.links.items() if (x := lk.length) is not None]
    out += [(x, f"links.{n}", "sides") for n, lk in m.links.items() for x in lk.sides or ()]
    out += [(abs(sl.offset), f"sliders.{n}", "offset") for n, sl in m.sliders.items() if sl.offset is not None]
    out += [(math.hypot(*p.local), f"points.{n}", "local") for n, p in m.points.items() if p.local is not None]
    return out


def pivot_span(m: Mechanism) -> tuple[float, tuple[str, str] | None]:
    """The ground pivots' largest distance apart [file units] and the two pivots that set it (None: one pivot)."""
    piv = [j for j in m.links[m.ground].joints if j in m.joints]
    pairs = [(math.dist(m.joints[a], m.joints[b]), (a, b)) for i, a in enumerate(piv) for b in piv[i + 1 :]]
    return max(pairs, default=(0.0, None))


def dimension_size(m: Mechanism) -> tuple[float, str]:
    """A mechanism written from dimensions: its size [file units] and what sets it (for messages) — its largest
    dimension or its ground pivots' span, whichever is larger. Never its hints: they may be anywhere."""
    dims = dimension_list(m)
    big = max(dims, default=(0.0, "", ""))
    span, pivots = pivot_span(m)
    if pivots is not None and span >= big[0]:
        return span, f"the distance of its ground pivots {pivots[0]} and {pivots[1]}"
    return big[0], f"its largest dimension, [{big[1]}] {big[2]}"


def reach(m: Mechanism) -> float:
    """How far apart an assembly's joints can be [file units], about: its dimensions' sum and its ground pivots'
    span (a slider's travel aside), an upper bound of its size that its hints never set."""
    return sum(d for d, _, _ in dimension_list(m)) + pivot_span(m)[0]


def check_proportions(m: Mechanism, probs: Problems) -> None:
    """In a file written from dimensions, every number that sets a length is in proportion: coordinates and
    dimensions within ±SIZES[1] (the largest the solver takes); a dimension at most FAR times the rest of the
    mechanism (its other dimensions and its pivots' span), the pivots at most FAR times its largest dimension
    apart; a hint at most FAR times the mechanism's size (:func:`dimension_size`) from the nearest ground pivot."""
    pivots = [j for j in m.links[m.ground].joints if j in m.joints]
    dims = dimension_list(m)
    for j in pivots:
        if max(map(abs, m.joints[j])) > SIZES[1]:
            probs.add(f"joints.{j}", f"({_xy(m.joints[j])}) {beyond_sizes(m.units)}")
    for x, entry, key in dims:
        if x > SIZES[1]:
            probs.add(entry, f"'{key}' = {x:.6g} {beyond_sizes(m.units)}")
    if probs.items:
        return
    span, pair = pivot_span(m)
    for i, (x, entry, key) in enumerate(dims):
        rest = max([span, *(d for k, (d, _, _) in enumerate(dims) if k != i)])
        if 0 < rest and x > FAR * rest:
            why = f"the rest of the mechanism's size ({rest:.6g} {m.units}: its other dimensions and its ground pivots)"
            far = f"at most {FAR:.0e} times (a typing error?)"
            probs.add(entry, f"'{key}' = {x:.6g} is {x / rest:.3g} times {why}: {far}")
    largest = max((d for d, _, _ in dims), default=0.0)
    if pair is not None and 0 < largest and span > FAR * largest:
        a, b = sorted(pair, key=lambda j: max(map(abs, m.joints[j])))
        what = f"ground pivots {a} and {b} are {span:.6g} {m.units} apart"
        probs.add(f"joints.{b}", f"{what}, {span / largest:.3g} times the largest dimension: at most {FAR:.0e} times")
    if not probs.items:
        _check_hints(m, pivots, probs)


def _check_hints(m: Mechanism, pivots: list[str], probs: Problems) -> None:
    """A moving joint's coordinates (a hint) within FAR times the mechanism's size of the nearest ground pivot."""
    size, why = dimension_size(m)
    fixed = set(m.links[m.ground].joints) | set(m.unplaced)
    for j, (x, y) in m.joints.items():
        if j in fixed or size <= 0:
            continue
        dist, near = min((max(abs(x - m.joints[p][0]), abs(y - m.joints[p][1])), p) for p in pivots)
        if dist > FAR * size:
            probs.add(
                f"joints.{j}",
                f"hint ({_xy((x, y))}) is {dist / size:.3g} times the mechanism's size ({size:.6g} {m.units}, {why}) "
                f"from the ground pivot {near}: at most {FAR:.0e} times (a typing error?)",
            )
        elif max(abs(x), abs(y)) > SIZES[1]:
            probs.add(f"joints.{j}", f"hint ({_xy((x, y))}) {beyond_sizes(m.units)}")


def _xy(xy: tuple[float, float]) -> str:
    return f"{xy[0]:.6g}, {xy[1]:.6g}"


def check_lengths(m: Mechanism, tol: float, probs: Problems) -> None:
    """In a file written from dimensions, a link's joints are as far apart as its dimensions say: none may be
    closer than ``tol`` of the mechanism's size (:func:`dimension_size`), which makes two joints one."""
    size, why = dimension_size(m)
    for n, lk in m.links.items():
        if lk.ground or not lk.dimensioned:
            continue
        corners = list(_local(lk, m.joints).values())
        pairs = [(i, k) for i in range(len(corners)) for k in range(i + 1, len(corners))]
        for i, k in pairs:
            if (d := math.dist(corners[i], corners[k])) <= tol * size:
                what = f"its dimensions put joints {lk.joints[i]} and {lk.joints[k]} {d:.3g} {m.units} apart"
                probs.add(
                    f"links.{n}", f"{what}, one joint at {tol:g} of the mechanism's size ({size:.6g} {m.units}: {why})"
                )


def check_ternaries(links: dict[str, Link], joints: dict[str, tuple[float, float]], probs: Problems) -> None:
    """Three sides give a triangle up to its mirror image: the coordinates of its three joints must show which."""
    for n, lk in links.items():
        if lk.sides is None or len(lk.sides) != 3:
            continue
        j0, j1, j2 = lk.joints
        fix = f"give rough coordinates of {j0}, {j1}, {j2}, or sides = [|{j0}{j1}|, |{j0}{j2}|] with the angle at {j0}"
        if any(j not in joints for j in lk.joints):
            probs.add(f"links.{n}", f"three sides give the triangle up to its mirror image: {fix}")
            continue
        p0, p1, p2 = (joints[j] for j in lk.joints)
        u, v = (p1[0] - p0[0], p1[1] - p0[1]), (p2[0] - p0[0], p2[1] - p0[1])
        if abs(u[0] * v[1] - u[1] * v[0]) <= HANDEDNESS_TOL * math.hypot(*u) * math.hypot(*v):
            why = "its coordinates are in a line, so they do not show which mirror image the three sides mean"
            probs.add(f"links.{n}", f"{why}: {fix}")


def place_joints(
    joints: dict[str, tuple[float, float]],
    links: dict[str, Link],
    sliders: dict[str, Slider],
    missing: dict[str, str],
    probs: Problems,
) -> dict[str, tuple[float, float]]:
    """Every joint with a position: the given ones, and the missing ones placed provisionally from the dimensions
    (a link with a placed joint is laid down through it, turned as its placed joints show or along +x)."""
    placed = dict(joints)
    todo = [j for j in missing if j not in placed]
    while todo:
        before = len(todo)
        for lk in links.values():
            if not lk.ground:
                _lay_link(lk, placed)
        for sl in sliders.values():
            if sl.joint not in placed and _frame_known(links, placed, sl.guide):
                placed[sl.joint] = _on_line(sl, links, placed)
        todo = [j for j in todo if j not in placed]
        if len(todo) == before:
            for j in todo:
                probs.add(missing[j], f"joint {show(j)} cannot be placed from the dimensions: give rough coordinates")
            break
    return {j: placed[j] for j in [*joints, *(j for j in missing if j in placed and j not in joints)]}


def _local(lk: Link, placed: dict[str, tuple[float, float]]) -> dict[str, tuple[float, float]]:
    """A dimensioned link's joints in its frame."""
    out = {lk.joints[0]: (0.0, 0.0)}
    if len(lk.joints) >= 2:
        out[lk.joints[1]] = (lk.length if lk.length is not None else lk.sides[0], 0.0)  # type: ignore[index]
    if lk.sides is not None:
        out[lk.joints[2]] = third_corner(lk, [placed.get(j, (0.0, 0.0)) for j in lk.joints])
    return out


def _lay_link(lk: Link, placed: dict[str, tuple[float, float]]) -> None:
    """Place a link's missing joints through its placed ones (turned as two placed joints show, else along +x)."""
    have = [j for j in lk.joints if j in placed]
    if not have or len(have) == len(lk.joints) or not lk.dimensioned:
        return
    loc = _local(lk, placed)
    turn = 0.0
    if len(have) >= 2:
        (a, b), (la, lb) = (placed[have[0]], placed[have[1]]), (loc[have[0]], loc[have[1]])
        turn = math.atan2(b[1] - a[1], b[0] - a[0]) - math.atan2(lb[1] - la[1], lb[0] - la[0])
    c, s = math.cos(turn), math.sin(turn)
    p, lp = placed[have[0]], loc[have[0]]
    for j in lk.joints:
        if j not in placed:
            dx, dy = loc[j][0] - lp[0], loc[j][1] - lp[1]
            placed[j] = (p[0] + c * dx - s * dy, p[1] + s * dx + c * dy)


def _frame_known(links: dict[str, Link], placed: dict[str, tuple[float, float]], guide: str) -> bool:
    """Whether a guide's frame is known from placed joints (the ground's always)."""
    lk = links[guide]
    return lk.ground or (len(lk.joints) >= 2 and all(j in placed for j in lk.joints[:2]))


def _frame(links: dict[str, Link], placed: dict[str, tuple[float, float]], guide: str) -> tuple[float, float, float]:
    """(x, y, θ) of a guide's frame from placed joints (the ground's is the world's)."""
    lk = links[guide]
    if lk.ground:
        return 0.0, 0.0, 0.0
    (x0, y0), (x1, y1) = placed[lk.joints[0]], placed[lk.joints[1]]
    return x0, y0, math.atan2(y1 - y0, x1 - x0)


def _on_line(sl: Slider, links: dict[str, Link], placed: dict[str, tuple[float, float]]) -> tuple[float, float]:
    """A slider's joint at s = 0 on its sliding line (provisional)."""
    x, y, th = _frame(links, placed, sl.guide)
    alpha = th + (sl.angle if sl.angle is not None else math.atan2(sl.axis[1], sl.axis[0]) - th)
    e = sl.offset or 0.0
    return x - e * math.sin(alpha), y + e * math.cos(alpha)


def axes_from_angles(
    sliders: dict[str, Slider], links: dict[str, Link], joints: dict[str, tuple[float, float]]
) -> dict[str, Slider]:
    """Sliders given by ``angle`` with their t = 0 ``axis``: the angle turned by the guide's frame as the
    coordinates draw it (the assembly turns it with the guide)."""
    out = {}
    for n, sl in sliders.items():
        if sl.angle is not None:
            th = _frame(links, joints, sl.guide)[2] + sl.angle
            sl = dataclasses.replace(sl, axis=(math.cos(th), math.sin(th)))
        out[n] = sl
    return out


def points_from_local(proto: Mechanism, points: dict[str, Point]) -> dict[str, Point]:
    """Points given by ``local`` with their t = 0 position ``at`` through their body's frame."""
    bodies = proto.bodies()
    return {
        n: dataclasses.replace(p, at=to_world(bodies[p.link], p.local)) if p.local is not None else p
        for n, p in points.items()
    }
