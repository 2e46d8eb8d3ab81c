"""A drag: a joint moved at t = 0, the whole displayed run solved again; a move past a limit stops at the limit.

A drag that would leave the motion unable to complete (the input passes a limit position, a loop cannot close) is
bisected between the last position that ran and the target (LIMIT_STEPS halvings, so the joint stops within 2⁻¹²
of the move from the limit) and the reply says what stopped it. Locked joints do not move; a joint of a locked link
slides on the circle its length allows about the link's other joint.
"""

from __future__ import annotations

import math
from typing import Any

from . import document as docs
from .session import LIMIT_STEPS, Frame, MessageError, Session


def drag(s: Session, msg: dict) -> dict[str, Any]:
    """``{"op": "drag", "joint": J, "x": …, "y": …, "gesture": any}``: the reply's ``limit`` (if any) says where the
    drag stopped and why; messages of one gesture make one undo step."""
    joint = msg.get("joint")
    if not isinstance(joint, str) or joint not in s.doc["joints"]:
        raise MessageError(f"drag: no joint {str(joint)[:40]!r}")
    if joint in s.locks["joints"]:
        raise MessageError(f"joint {joint} is locked")
    x, y = _allowed(s, joint, docs.number(msg.get("x"), "x"), docs.number(msg.get("y"), "y"))
    gesture = msg.get("gesture")
    new_gesture = gesture is None or not isinstance(gesture, int | str) or gesture != s.gesture
    s.gesture = gesture if isinstance(gesture, int | str) else None
    running = s.frame.mech is not None and s.frame.error is None
    doc = docs.move_joint(s.doc, joint, x, y)
    frame = s._frame(doc, drawn=_closed(s))
    if _runs(frame) or not running:
        s._accept(doc, frame, history=new_gesture)
        return s.state()
    return _to_limit(s, joint, (x, y), frame, new_gesture)


def _closed(s: Session) -> bool:
    """Whether the drawing's coordinates are its assembly (a mechanism runs), so a moved joint needs no new t = 0
    assembly: every link's dimensions are restated from the coordinates."""
    return s.frame.mech is not None and s.frame.draft is None


def _runs(frame: Frame) -> bool:
    return frame.mech is not None and frame.error is None and frame.draft is None


def _allowed(s: Session, joint: str, x: float, y: float) -> tuple[float, float]:
    """The target moved onto what locked links allow: one locked link through the joint keeps its length (the
    joint goes to the nearest point of that circle); two or more hold it still."""
    locked = [n for n in s.locks["links"] if joint in s.doc["links"][n]["joints"] and len(s.doc["links"][n]["joints"])]
    if not locked:
        return x, y
    if len(locked) > 1:
        raise MessageError(f"joint {joint} is held by the locked links {', '.join(sorted(locked))}")
    lk = s.doc["links"][locked[0]]
    others = [j for j in lk["joints"] if j != joint]
    if len(others) != 1:
        raise MessageError(f"joint {joint} is on the locked plate {locked[0]}")
    cx, cy = s.doc["joints"][others[0]]
    r = math.dist(s.doc["joints"][joint], (cx, cy))
    d = math.hypot(x - cx, y - cy)
    if d <= 1e-12 * max(r, 1.0):
        return tuple(s.doc["joints"][joint])
    return cx + r * (x - cx) / d, cy + r * (y - cy) / d


def _to_limit(s: Session, joint: str, target: tuple[float, float], failed: Frame, new_gesture: bool) -> dict:
    """Bisect between where the joint runs and the target; keep the last position that runs."""
    good, bad = tuple(s.doc["joints"][joint]), target
    best: tuple[dict, Frame] | None = None
    for _ in range(LIMIT_STEPS):
        mid = ((good[0] + bad[0]) / 2, (good[1] + bad[1]) / 2)
        doc = docs.move_joint(s.doc, joint, *mid)
        frame = s._frame(doc, drawn=_closed(s))
        if _runs(frame):
            good, best = mid, (doc, frame)
        else:
            bad, failed = mid, frame
    why = failed.error or failed.draft or "the motion cannot be completed"
    if best is not None:
        s._accept(best[0], best[1], history=new_gesture)
    units = s.frame.mech.units if s.frame.mech is not None else ""
    limit = f"{joint} stopped at ({good[0]:.6g}, {good[1]:.6g}) {units}: a limit — {why}"
    return s.state(limit=limit)
