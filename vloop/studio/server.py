"""``vloop studio``: the session served on 127.0.0.1 (Starlette on uvicorn, one WebSocket per page).

Safe by default, as Jupyter's server: bound to the loopback address; a random token per start, required on every
request and on the WebSocket (``?token=``); the Host and Origin headers must name this server (no other site's
page, no DNS rebinding); files only inside the folder it started on (:mod:`.jail`); messages of at most
``MAX_MESSAGE`` bytes, each answered — a malformed one with an error reply. Slow work runs away from the socket:
validation in a thread that waits on its child process, synthesis in a worker process.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import hmac
import json
import multiprocessing
import secrets
import time
from pathlib import Path
from typing import Any

from .page import render
from .session import SLOW, Session
from .work import lower_priority

MAX_MESSAGE = 1 << 20  # bytes of one WebSocket message
# no per-message deflate: a frame's columns are float64 in base64 (deflate takes longer than sending them on the
# loopback interface, and a drag's reply is replaced a moment later)
UVICORN = {"log_level": "warning", "ws_max_size": MAX_MESSAGE, "ws_per_message_deflate": False}


def _allowed_hosts(port: int) -> set[str]:
    return {f"127.0.0.1:{port}", f"localhost:{port}"}


class Guard:
    """The checks every request passes: the token, the Host, the Origin."""

    def __init__(self, token: str, port: int) -> None:
        self.token, self.port = token, port

    def refusal(self, headers: Any, query: Any) -> str | None:
        if not hmac.compare_digest(str(query.get("token", "")), self.token):
            return "a valid token is needed (the address vloop studio printed)"
        if headers.get("host", "") not in _allowed_hosts(self.port):
            return "this server answers to 127.0.0.1 and localhost only"
        origin = headers.get("origin")
        if origin is not None and origin not in {f"http://{h}" for h in _allowed_hosts(self.port)}:
            return "requests from another site's page are refused"
        return None


def app(session: Session, token: str, port: int) -> Any:
    """The ASGI app over ``session``."""
    from starlette.applications import Starlette
    from starlette.responses import HTMLResponse, PlainTextResponse
    from starlette.routing import Route, WebSocketRoute
    from starlette.websockets import WebSocketDisconnect

    guard = Guard(token, port)
    lock = asyncio.Lock()
    pools: dict[str, Any] = {}

    async def page(request: Any) -> Any:
        why = guard.refusal(request.headers, request.query_params)
        if why:
            return PlainTextResponse(why, status_code=403)
        host = request.headers["host"]
        headers = {"Cache-Control": "no-store", "X-Frame-Options": "DENY", "Referrer-Policy": "no-referrer"}
        return HTMLResponse(render(f"ws://{host}", token), headers=headers)

    async def view(request: Any) -> Any:
        why = guard.refusal(request.headers, request.query_params)
        if why:
            return PlainTextResponse(why, status_code=403)
        async with lock:
            reply = await asyncio.to_thread(session.handle, {"op": "page"})
        if not reply["ok"]:
            return PlainTextResponse(reply["error"], status_code=409)
        return HTMLResponse(reply["html"], headers={"Cache-Control": "no-store"})

    async def socket(ws: Any) -> None:
        why = guard.refusal(ws.headers, ws.query_params)
        if why:
            await ws.close(code=1008, reason=why[:120])
            return
        await ws.accept()
        try:
            while True:
                text = await ws.receive_text()
                await _answer(ws, text, session, lock, pools)
        except (WebSocketDisconnect, RuntimeError):
            return

    @contextlib.asynccontextmanager
    async def lifespan(_app: Any) -> Any:
        yield
        for pool in pools.values():  # Ctrl-C: workers stopped, nothing left running
            if hasattr(pool, "shutdown"):
                pool.shutdown(wait=False, cancel_futures=True)

    routes = [Route("/", page), Route("/view", view), WebSocketRoute("/ws", socket)]
    return Starlette(routes=routes, lifespan=lifespan)


async def _answer(ws: Any, text: str, session: Session, lock: asyncio.Lock, pools: dict) -> None:
    """One message: parsed, answered (slow work started in a worker, its reply sent when done)."""
    if len(text) > MAX_MESSAGE:
        await ws.send_text(json.dumps({"op": None, "ok": False, "error": f"a message of at most {MAX_MESSAGE} bytes"}))
        return
    try:
        msg = json.loads(text)
    except (ValueError, RecursionError):
        await ws.send_text(json.dumps({"op": None, "ok": False, "error": "a message is one JSON object"}))
        return
    if isinstance(msg, dict) and msg.get("op") in SLOW:
        asyncio.get_running_loop().create_task(_slow(ws, msg, session, lock, pools))
        return
    async with lock:  # a quick message is answered in the loop itself: no thread to wake on a busy machine
        started = time.perf_counter()
        reply = session.handle(msg)
        reply["ms"] = 1e3 * (time.perf_counter() - started)  # the session's time, for the page's own timing
    await _send(ws, reply)


async def _send(ws: Any, reply: dict) -> None:
    """A reply as JSON; one that JSON cannot carry (a non-finite number) is said, never sent as NaN; a page that has
    gone away is let go."""
    try:
        text = json.dumps(reply, allow_nan=False, default=str)
    except ValueError:
        text = json.dumps({"id": reply.get("id"), "op": reply.get("op"), "ok": False, "error": "a non-finite number"})
    try:
        await ws.send_text(text)
    except (RuntimeError, OSError):  # the socket closed meanwhile (a reload, a closed tab)
        return


async def _slow(ws: Any, msg: dict, session: Session, lock: asyncio.Lock, pools: dict) -> None:
    op = msg["op"]
    if op in pools.get("busy", set()):
        await ws.send_text(json.dumps({"id": msg.get("id"), "op": op, "ok": False, "error": f"a {op} is running"}))
        return
    async with lock:
        try:
            work = session.job(msg)
        except Exception as exc:  # the job's own checks: the message's fault, answered
            await ws.send_text(json.dumps({"id": msg.get("id"), "op": op, "ok": False, "error": str(exc)[:500]}))
            return
    pools.setdefault("busy", set()).add(op)
    await ws.send_text(json.dumps({"id": msg.get("id"), "op": op, "ok": True, "started": True}))
    try:
        answer = await asyncio.get_running_loop().run_in_executor(_pool(pools, op), work)
        async with lock:
            reply = session.finish(msg, answer)
    except Exception as exc:  # a worker that failed: said, the server goes on
        reply = {"id": msg.get("id"), "op": op, "ok": False, "error": f"{op} failed: {str(exc)[:400]}"}
    finally:
        pools["busy"].discard(op)
    await _send(ws, reply)


def _pool(pools: dict, op: str) -> Any:
    """Synthesis in one worker process (it computes); validation in a thread (it waits on ``vloop validate``)."""
    if op not in pools:
        if op == "synthesize":
            ctx = multiprocessing.get_context("spawn")
            pools[op] = concurrent.futures.ProcessPoolExecutor(
                max_workers=1, mp_context=ctx, initializer=lower_priority
            )
        else:
            pools[op] = concurrent.futures.ThreadPoolExecutor(max_workers=1)
    return pools[op]


def start_session(target: str | Path | None) -> tuple[Session, Path]:
    """The session for ``vloop studio [FILE|FOLDER]``: the folder is the jail; a file in it is opened."""
    path = Path(target) if target is not None else Path.cwd()
    folder = path if path.is_dir() else path.parent
    session = Session(folder)
    if path.is_file():
        reply = session.handle({"op": "open", "path": path.name})
        if not reply["ok"]:
            raise ValueError(reply["error"])
    return session, folder.resolve()


def serve(target: str | Path | None, *, port: int = 0, browser: bool = True, echo: Any = print) -> int:
    """Run the studio until Ctrl-C: bound to 127.0.0.1, the address (with its token) printed and opened."""
    import socket as sockets

    import uvicorn

    session, folder = start_session(target)
    token = secrets.token_urlsafe(24)
    sock = sockets.socket(sockets.AF_INET, sockets.SOCK_STREAM)
    sock.setsockopt(sockets.SOL_SOCKET, sockets.SO_REUSEADDR, 1)
    sock.bind(("127.0.0.1", port))
    sock.listen(128)  # connections wait for the server from now on: the printed address answers at once
    port = sock.getsockname()[1]
    url = f"http://127.0.0.1:{port}/?token={token}"
    echo(f"vloop studio on {folder}\n  {url}\n(Ctrl-C stops it)", flush=True)
    config = uvicorn.Config(app(session, token, port), lifespan="on", **UVICORN)
    server = uvicorn.Server(config)
    if browser:
        import threading
        import webbrowser

        threading.Timer(0.5, webbrowser.open, args=(url,)).start()
    server.run(sockets=[sock])
    return 0


class Background:
    """The studio served from a thread of this process (tests, benchmarks, a notebook): ``.url`` (with its token),
    ``.stop()``."""

    def __init__(self, session: Session, port: int = 0) -> None:
        import socket as sockets
        import threading

        import uvicorn

        self.token = secrets.token_urlsafe(24)
        self.sock = sockets.socket(sockets.AF_INET, sockets.SOCK_STREAM)
        self.sock.bind(("127.0.0.1", port))
        self.port = self.sock.getsockname()[1]
        self.url = f"http://127.0.0.1:{self.port}/?token={self.token}"
        config = uvicorn.Config(app(session, self.token, self.port), **UVICORN)
        self.server = uvicorn.Server(config)
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)
        self.thread.start()
        while not self.server.started and self.thread.is_alive():
            self.thread.join(0.02)

    def stop(self) -> None:
        self.server.should_exit = True
        self.thread.join(10)
        self.sock.close()
