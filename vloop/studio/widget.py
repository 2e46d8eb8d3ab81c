"""The studio in a notebook: an anywidget whose front end is the studio page's (viewer + studio scripts), talking to
the kernel through the widget's custom messages — the same :class:`Session` and the same messages as the web app.

Slow work (synthesis, validation) runs in a thread of the kernel and answers when done. Files: only inside
``folder`` (default: none — the widget then reads and writes no file)."""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

import anywidget
import traitlets

from .page import widget_parts
from .session import SLOW, Session

_ESM = """
export default {
  render({ model, el }) {
    const parts = model.get("parts");
    const host = document.createElement("div");
    host.className = "vloop-studio-widget";
    const style = document.createElement("style");
    style.textContent = parts.css;
    host.append(style);
    const body = document.createElement("div");
    body.innerHTML = parts.panel + parts.body;
    host.append(body);
    el.append(host);
    const listeners = [];
    window.vloopStudioTransport = {
      ready: Promise.resolve(),
      send: (text) => model.send({ text }),
      onmessage: null,
    };
    const T = window.vloopStudioTransport;
    model.on("msg:custom", (msg) => T.onmessage && T.onmessage(msg.text));
    for (const code of [parts.viewer, parts.studio]) new Function(code)();
  },
};
"""


class Studio(anywidget.AnyWidget):
    """``vloop.studio(mech)``: the editor inline, the drawing's session in the kernel (``.session``)."""

    _esm = _ESM
    parts = traitlets.Dict().tag(sync=True)

    def __init__(self, mechanism: Any = None, *, folder: str | Path | None = None, samples: int = 360) -> None:
        super().__init__(parts=widget_parts())
        doc = None
        if mechanism is not None:
            from vloop.mechanism import to_dict

            doc = to_dict(mechanism)
        self.session = Session(folder, doc, samples=samples)
        self._lock = threading.Lock()
        self.on_msg(self._receive)

    def _receive(self, _widget: Any, content: Any, _buffers: Any) -> None:
        text = content.get("text") if isinstance(content, dict) else None
        try:
            msg = json.loads(text) if isinstance(text, str) else None
        except ValueError:
            msg = None
        if isinstance(msg, dict) and msg.get("op") in SLOW:
            threading.Thread(target=self._slow, args=(msg,), daemon=True).start()
            return
        with self._lock:
            reply = self.session.handle(msg)
        self.send({"text": json.dumps(reply, allow_nan=False, default=str)})

    def _slow(self, msg: dict) -> None:
        with self._lock:
            try:
                work = self.session.job(msg)
            except Exception as exc:  # the job's own checks: answered as an error
                self.send({"text": json.dumps({"id": msg.get("id"), "op": msg["op"], "ok": False, "error": str(exc)})})
                return
        try:
            answer = work()
            with self._lock:
                reply = self.session.finish(msg, answer)
        except Exception as exc:  # a failed worker is said, the kernel goes on
            reply = {"id": msg.get("id"), "op": msg["op"], "ok": False, "error": f"{msg['op']} failed: {exc}"}
        self.send({"text": json.dumps(reply, allow_nan=False, default=str)})
