"""The studio's session: one drawing, its undo history and locks; a message (a dict) in, a reply (a dict) out.

Every host (the local web server, the notebook widget, a test) passes the browser's messages to
:meth:`Session.handle` and sends back what it returns; nothing here knows about sockets. A message is
``{"op": NAME, "id": any, ...arguments}``; the reply is ``{"id": same, "op": NAME, "ok": True, ...}`` or
``{"id": same, "op": NAME, "ok": False, "error": one line}`` — a malformed or hostile message gets the second, never
an exception. After an edit the reply carries ``state``: the document, the viewer's page data solved by vloop's
core over the displayed samples (``payload``), what the drawing is (mobility, loops and their branch names, Grashof
classes, transmission angles, health) and any stop or limit met. Slow work (synthesis, validation against Pinocchio
and Exudyn) is split in two so a host can run it in a worker: :meth:`Session.job` returns a callable that needs
no session, and :meth:`Session.finish` takes its answer.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from vloop.errors import MotionError, VloopError

from . import document as docs
from .jail import JailError, inside, listing

DISPLAY_SAMPLES = 360  # samples solved for the screen: one turn at 1° (a crank that turns once over the run)
HISTORY = 200  # undo steps kept
LIMIT_STEPS = 12  # bisection steps between the last good drag position and the target: 2⁻¹² of the move


class MessageError(ValueError):
    """A message that cannot be carried out (its reply says why)."""


@dataclass
class Frame:
    """What the screen shows of one document: the Mechanism and its run over the displayed samples, or why not."""

    mech: Any = None
    system: Any = None
    result: Any = None
    payload: dict | None = None
    info: dict = field(default_factory=dict)
    error: str | None = None  # a motion that stopped (the payload shows the samples before the stop)
    draft: str | None = None  # not yet a mechanism (the document is drawn as it is)


def catalog() -> dict[str, Path]:
    """The catalog's mechanism files by name (vloop's source tree's mechanisms/)."""
    folder = Path(__file__).resolve().parents[2] / "mechanisms"
    return {p.stem: p for p in sorted(folder.glob("*.toml"))}


class Session:
    """One studio: the document being edited, its frame, undo/redo, locks, synthesis candidates.

    ``root``: the folder files are read from and written to (None: no file access); ``samples``: how many samples
    of the run the screen shows (solved over the file's time span)."""

    def __init__(self, root: str | Path | None = None, doc: dict | None = None, *, samples: int = DISPLAY_SAMPLES):
        self.root = Path(root).resolve() if root is not None else None
        self.samples = int(samples)
        self.doc = doc if doc is not None else docs.empty()
        self.undo: list[dict] = []
        self.redo: list[dict] = []
        self.locks: dict[str, set[str]] = {"joints": set(), "links": set()}
        self.gesture: Any = None
        self.targets: list[list[float]] = []
        self.candidates: list[Any] = []
        self.frame = self._frame(self.doc)

    # ------------------------------------------------------------------ the one door

    def handle(self, msg: Any) -> dict[str, Any]:
        """The reply to one message (never raises for anything the message holds)."""
        ident = msg.get("id") if isinstance(msg, dict) else None
        ident = ident if isinstance(ident, int | str) and not isinstance(ident, bool) and len(str(ident)) < 64 else None
        op = msg.get("op") if isinstance(msg, dict) else None
        if not isinstance(op, str) or op not in OPS:
            return {"id": ident, "op": str(op)[:40], "ok": False, "error": f"unknown message {str(op)[:40]!r}"}
        try:
            reply = OPS[op](self, msg)
        except (MessageError, docs.EditError, JailError, VloopError) as exc:
            return {"id": ident, "op": op, "ok": False, "error": str(exc).splitlines()[0][:500]}
        except (KeyError, TypeError, ValueError, AttributeError, IndexError, OverflowError) as exc:
            return {"id": ident, "op": op, "ok": False, "error": f"malformed {op} message ({type(exc).__name__})"}
        except Exception as exc:  # a fault of vloop's, not the message's: said as such, the session goes on
            what = f"{type(exc).__name__}: {str(exc).splitlines()[0][:300] if str(exc) else ''}"
            return {"id": ident, "op": op, "ok": False, "error": f"internal error in {op} ({what}): please report it"}
        return {"id": ident, "op": op, "ok": True, **reply}

    def state(self, **extra: Any) -> dict[str, Any]:
        f = self.frame
        return {"state": {
            "doc": self.doc, "payload": f.payload, "info": f.info, "error": f.error, "draft": f.draft,
            "locks": {k: sorted(v) for k, v in self.locks.items()}, "undo": len(self.undo), "redo": len(self.redo),
            "targets": self.targets, **extra,
        }}  # fmt: skip

    # ------------------------------------------------------------------ solving a document

    def _frame(self, doc: dict, *, drawn: bool = False) -> Frame:
        """The document as vloop reads it, solved over the displayed samples (a draft or a stop said in the frame);
        ``drawn``: read from its coordinates alone (:func:`document.file_dict`)."""
        import vloop
        from vloop.compiler import compile_system
        from vloop.core.solver import solve

        try:
            mech = vloop.from_dict(docs.file_dict(doc, drawn=drawn), source="studio")
            system = compile_system(mech)
        except VloopError as exc:
            return Frame(draft=str(exc).splitlines()[0])
        times = np.linspace(float(mech.times[0]), float(mech.times[-1]), self.samples) if len(mech.times) > 1 else None
        error = None
        try:
            result = solve(system, times)
        except MotionError as exc:
            error, result = str(exc).splitlines()[0], exc.partial
            if result is None or not len(result):
                return Frame(mech=mech, system=system, draft=f"the motion cannot start: {error}")
        return self._framed(mech, system, result, error)

    def _framed(self, mech: Any, system: Any, result: Any, error: str | None) -> Frame:
        from vloop.views.view import build_payload

        from .info import describe

        payload = build_payload(mech, result, system=system, error=error, targets=self.targets or None, deflate=False)
        return Frame(mech, system, result, payload, describe(mech, system, result), error)

    def _accept(self, doc: dict, frame: Frame | None = None, *, history: bool = True) -> None:
        if history:
            self.undo = [*self.undo[-HISTORY + 1 :], self.doc]
            self.redo = []
        self.frame = frame if frame is not None else self._frame(doc)
        if self.frame.mech is not None:  # the drawing shows the assembly vloop made (closed to round-off)
            doc = docs.edited(doc)
            for j in doc["joints"]:
                if j in self.frame.mech.joints:
                    doc["joints"][j] = [float(v) for v in self.frame.mech.joints[j]]
        self.doc = doc

    def _edit(self, doc: dict) -> dict[str, Any]:
        """An edit that must leave a drawing vloop can read or a draft; refused if it breaks a mechanism."""
        frame = self._frame(doc)
        if frame.draft and self.frame.mech is not None and self.frame.error is None:
            raise MessageError(frame.draft)
        self._check_locks(frame)
        self._accept(doc, frame)
        return self.state()

    def _check_locks(self, frame: Frame) -> None:
        if frame.mech is None:
            return
        for j in self.locks["joints"]:
            if j in self.doc["joints"] and j in frame.mech.joints:
                if math.dist(self.doc["joints"][j], frame.mech.joints[j]) > 1e-9 * frame.mech.scale:
                    raise MessageError(f"joint {j} is locked: this edit would move it")

    # ------------------------------------------------------------------ work for a worker

    def job(self, msg: dict) -> Callable[[], Any]:
        """A callable (no session inside) that does the slow part of ``msg`` ("synthesize" or "validate")."""
        from .work import job

        return job(self, msg)

    def finish(self, msg: dict, answer: Any) -> dict[str, Any]:
        """The reply to ``msg`` once its job's ``answer`` is in."""
        from .work import finish

        ident = msg.get("id") if isinstance(msg, dict) else None
        try:
            return {"id": ident, "op": msg["op"], "ok": True, **finish(self, msg, answer)}
        except (MessageError, docs.EditError, VloopError, KeyError, TypeError, ValueError) as exc:
            return {"id": ident, "op": msg.get("op"), "ok": False, "error": str(exc).splitlines()[0][:500]}


# ---------------------------------------------------------------------- the operations


def _state(s: Session, msg: dict) -> dict:
    return s.state()


def _new(s: Session, msg: dict) -> dict:
    doc = docs.empty(units=msg.get("units", "mm"))
    doc = docs.set_meta(doc, units=doc["units"])
    s.targets, s.candidates = [], []
    s._accept(doc)
    return s.state()


def _open(s: Session, msg: dict) -> dict:
    """A file inside the folder (``path``) or a catalog mechanism (``catalog``: its name)."""
    import vloop
    from vloop.mechanism import to_dict

    if "catalog" in msg:
        found = catalog().get(msg["catalog"]) if isinstance(msg["catalog"], str) else None
        if found is None:
            raise MessageError(f"no catalog mechanism {str(msg['catalog'])[:40]!r}")
        path = found
    else:
        path = inside(s.root, msg.get("path"), {".toml"})
        if not path.is_file():
            raise MessageError(f"{msg.get('path')!s:.80}: no such file in the studio's folder")
    doc = to_dict(vloop.load(path))
    s.targets, s.candidates = [], []
    s.locks = {"joints": set(), "links": set()}
    s._accept(doc)
    return s.state()


def _files(s: Session, msg: dict) -> dict:
    return {"files": listing(s.root), "catalog": list(catalog()), "folder": bool(s.root)}


def _add_joint(s: Session, msg: dict) -> dict:
    doc, name = docs.add_joint(s.doc, msg.get("x"), msg.get("y"), ground=bool(msg.get("ground")), name=msg.get("name"))
    s._accept(doc)
    return {**s.state(), "name": name}


def _add_link(s: Session, msg: dict) -> dict:
    doc, name = docs.add_link(s.doc, msg.get("joints"), name=msg.get("name"))
    return {**s._edit(doc), "name": name}


def _add_slider(s: Session, msg: dict) -> dict:
    doc, name = docs.add_slider(s.doc, msg.get("joint"), msg.get("angle", 0.0), name=msg.get("name"))
    return {**s._edit(doc), "name": name}


def _set_driver(s: Session, msg: dict) -> dict:
    return s._edit(docs.set_driver(s.doc, msg.get("link"), msg.get("omega", 2 * math.pi), msg.get("alpha", 0.0),
                                   msg.get("theta0")))  # fmt: skip


def _set_length(s: Session, msg: dict) -> dict:
    if msg.get("link") in s.locks["links"]:
        raise MessageError(f"link {msg['link']} is locked: its length stays")
    return s._edit(docs.set_length(s.doc, msg.get("link"), msg.get("length")))


def _set_sides(s: Session, msg: dict) -> dict:
    if msg.get("link") in s.locks["links"]:
        raise MessageError(f"link {msg['link']} is locked: its sides stay")
    return s._edit(docs.set_sides(s.doc, msg.get("link"), msg.get("sides"), msg.get("angle")))


def _set_joint(s: Session, msg: dict) -> dict:
    """Typed coordinates of a joint (what a drag does, to the exact numbers)."""
    return _drag(s, {**msg, "gesture": object()})


def _set_time(s: Session, msg: dict) -> dict:
    return s._edit(docs.set_time(s.doc, msg.get("start"), msg.get("stop"), msg.get("step")))


def _set_meta(s: Session, msg: dict) -> dict:
    return s._edit(docs.set_meta(s.doc, msg.get("name"), msg.get("title"), msg.get("units")))


def _delete(s: Session, msg: dict) -> dict:
    doc = docs.delete(s.doc, msg.get("name"))
    s.locks = {k: {n for n in v if n in doc["joints"] or n in doc["links"]} for k, v in s.locks.items()}
    s._accept(doc)
    return s.state()


def _lock(s: Session, msg: dict) -> dict:
    kind, name = msg.get("kind"), msg.get("name")
    if kind not in s.locks or not isinstance(name, str):
        raise MessageError("lock: kind 'joints' or 'links' and a name")
    if name not in (s.doc["joints"] if kind == "joints" else s.doc["links"]):
        raise MessageError(f"lock: no {kind[:-1]} {name[:40]!r}")
    (s.locks[kind].add if msg.get("on", True) else s.locks[kind].discard)(name)
    return s.state()


def _undo(s: Session, msg: dict) -> dict:
    return _step(s, s.undo, s.redo, "undo")


def _redo(s: Session, msg: dict) -> dict:
    return _step(s, s.redo, s.undo, "redo")


def _step(s: Session, take: list, give: list, what: str) -> dict:
    if not take:
        raise MessageError(f"nothing to {what}")
    give.append(s.doc)
    doc = take.pop()
    s._accept(doc, history=False)
    s.gesture = None
    return s.state()


def _drag(s: Session, msg: dict) -> dict:
    from .drag import drag

    return drag(s, msg)


def _save(s: Session, msg: dict) -> dict:
    import vloop

    if s.frame.mech is None:
        raise MessageError(f"not yet a mechanism to save: {s.frame.draft}")
    path = inside(s.root, msg.get("path"), {".toml"})
    vloop.save(s.frame.mech, path)
    return {"path": path.relative_to(s.root).as_posix()}


def _export(s: Session, msg: dict) -> dict:
    from vloop.views.export import configuration, write_drawing, write_dxf

    fmt = msg.get("format")
    if fmt not in ("svg", "pdf", "dxf"):
        raise MessageError("export: format svg, pdf or dxf")
    if s.frame.result is None:
        raise MessageError(f"not yet a mechanism to export: {s.frame.draft}")
    path = inside(s.root, msg.get("path"), {f".{fmt}"})
    k = int(msg.get("sample", 0))
    res = s.frame.result
    if not 0 <= k < len(res):
        raise MessageError(f"export: sample {k} is not one of the {len(res)} shown")
    one = configuration(s.frame.mech, float(res.t[k]))
    (write_dxf if fmt == "dxf" else write_drawing)(s.frame.mech, one, path)
    return {"path": path.relative_to(s.root).as_posix()}


def _page(s: Session, msg: dict) -> dict:
    """The viewer page of the drawing's run as the file states it (every sample, as ``vloop view`` writes)."""
    from vloop.views.view import render, solve_for_view

    if s.frame.mech is None:
        raise MessageError(f"not yet a mechanism to view: {s.frame.draft}")
    result, error = solve_for_view(s.frame.mech)
    return {"html": render(s.frame.mech, result, error=error)}


def _targets(s: Session, msg: dict) -> dict:
    """The synthesis's target points [[x, y], ...] or poses [[x, y, angle], ...] (drawn as numbered crosses)."""
    pts = msg.get("points")
    if not isinstance(pts, list) or len(pts) > 12:
        raise MessageError("targets: a list of at most 12 points")
    s.targets = [[docs.number(v, "target") for v in p] for p in pts if isinstance(p, list) and len(p) in (2, 3)]
    if len(s.targets) != len(pts):
        raise MessageError("targets: each one [x, y] or [x, y, angle]")
    if s.frame.mech is not None and s.frame.result is not None:
        s.frame = s._framed(s.frame.mech, s.frame.system, s.frame.result, s.frame.error)
    return s.state()


def _take_candidate(s: Session, msg: dict) -> dict:
    """A synthesis candidate (its mechanism file's structure, kept from the search) taken into the editor."""
    k = msg.get("index")
    if not isinstance(k, int) or isinstance(k, bool) or not 0 <= k < len(s.candidates):
        raise MessageError(f"take: no candidate {str(k)[:20]} (there are {len(s.candidates)})")
    s._accept(copy.deepcopy(s.candidates[k]))
    return s.state()


def _worker_only(s: Session, msg: dict) -> dict:
    raise MessageError(f"{msg['op']} runs in a worker: the host calls Session.job and Session.finish")


OPS: dict[str, Callable[[Session, dict], dict]] = {
    "state": _state, "new": _new, "open": _open, "files": _files, "add_joint": _add_joint, "add_link": _add_link,
    "add_slider": _add_slider, "set_driver": _set_driver, "set_length": _set_length, "set_sides": _set_sides,
    "set_joint": _set_joint, "set_time": _set_time,
    "set_meta": _set_meta, "delete": _delete, "lock": _lock, "undo": _undo, "redo": _redo, "drag": _drag,
    "save": _save, "export": _export, "page": _page, "targets": _targets, "take": _take_candidate,
    "synthesize": _worker_only, "validate": _worker_only,
}  # fmt: skip
SLOW = ("synthesize", "validate")
