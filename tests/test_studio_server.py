"""The studio's web app refuses what it must: no token, a wrong token, another site's Origin, a Host that is not
this machine's loopback name, paths out of its folder (symlinks included) — and 1,000 random messages each get a
reply (an error where they make no sense) with the server still answering and nothing written outside its folder."""

from __future__ import annotations

import html
import json
import os
from pathlib import Path

import pytest

pytest.importorskip("starlette", reason="the studio's extra is not installed (pip install -e '.[studio]')")
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from starlette.testclient import TestClient
from starlette.websockets import WebSocketDisconnect

from vloop.studio.server import app
from vloop.studio.session import OPS, Session

PORT = 8765
TOKEN = "t0ken-for-tests"
HOST = {"host": f"127.0.0.1:{PORT}"}


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    base = tmp_path_factory.mktemp("jail")
    root, outside = base / "root", base / "outside"
    root.mkdir()
    outside.mkdir()
    (root / "escape").symlink_to(outside)
    session = Session(root)
    session.handle({"op": "open", "catalog": "fourbar_textbook_example"})
    client = TestClient(app(session, TOKEN, PORT), base_url=f"http://127.0.0.1:{PORT}")
    return client, root, outside


def test_the_page_needs_the_token_host_and_origin(served) -> None:
    client, _, _ = served
    assert client.get(f"/?token={TOKEN}", headers=HOST).status_code == 200
    assert client.get("/", headers=HOST).status_code == 403
    assert client.get("/?token=wrong", headers=HOST).status_code == 403
    assert client.get(f"/?token={TOKEN}", headers={"host": f"evil.example:{PORT}"}).status_code == 403
    other = {**HOST, "origin": "http://evil.example"}
    assert client.get(f"/?token={TOKEN}", headers=other).status_code == 403
    page = html.unescape(client.get(f"/?token={TOKEN}", headers=HOST).text)
    assert "connect-src ws://127.0.0.1:8765" in page and "default-src 'none'" in page


def test_the_socket_needs_the_token_and_origin(served) -> None:
    client, _, _ = served
    for url, headers in (
        ("/ws", HOST),
        ("/ws?token=no", HOST),
        (f"/ws?token={TOKEN}", {**HOST, "origin": "http://x.org"}),
    ):
        with pytest.raises(WebSocketDisconnect) as exc, client.websocket_connect(url, headers=headers) as ws:
            ws.receive_text()
        assert exc.value.code == 1008
    with client.websocket_connect(f"/ws?token={TOKEN}", headers={**HOST, "origin": f"http://127.0.0.1:{PORT}"}) as ws:
        ws.send_text(json.dumps({"op": "state", "id": 1}))
        reply = json.loads(ws.receive_text())
    assert reply["ok"] and reply["id"] == 1 and reply["state"]["info"]["mobility"]["M"] == 1


def test_paths_out_of_the_folder_are_refused(served) -> None:
    client, _, outside = served
    with client.websocket_connect(f"/ws?token={TOKEN}", headers=HOST) as ws:
        for path in ("../x.toml", str(outside / "x.toml"), "escape/x.toml", "escape/../../x.toml"):
            for op in ("save", "open"):
                ws.send_text(json.dumps({"op": op, "path": path}))
                reply = json.loads(ws.receive_text())
                assert reply["ok"] is False, (op, path)
    assert list(outside.iterdir()) == []


messages = st.one_of(
    st.fixed_dictionaries(
        {"op": st.sampled_from(sorted(set(OPS) - {"validate", "synthesize", "page"}))},
        optional={
            "id": st.one_of(st.integers(), st.text(max_size=5)),
            "joint": st.sampled_from(["A", "B", "O2", "O4", "Z", ""]),
            "x": st.one_of(st.floats(allow_nan=True), st.integers(), st.text(max_size=3), st.none()),
            "y": st.one_of(st.floats(-1e3, 1e3), st.none()),
            "path": st.one_of(
                st.text(max_size=20), st.sampled_from(["../a.toml", "/etc/x.toml", "escape/a.toml", "a.toml"])
            ),
            "link": st.sampled_from(["l2", "l3", "l4", "ground", "x"]),
            "length": st.one_of(st.floats(), st.integers(-5, 500)),
            "joints": st.lists(st.sampled_from(["A", "B", "O2", "O4", "Q"]), max_size=4),
            "catalog": st.text(max_size=10),
            "format": st.sampled_from(["svg", "pdf", "dxf", "exe"]),
            "points": st.lists(st.lists(st.floats(-1e3, 1e3), max_size=4), max_size=4),
            "name": st.text(max_size=8),
            "kind": st.sampled_from(["joints", "links", "x"]),
            "index": st.integers(-2, 3),
        },
    ),
    st.recursive(
        st.none() | st.booleans() | st.integers() | st.text(max_size=10),
        lambda c: st.lists(c, max_size=3) | st.dictionaries(st.text(max_size=5), c, max_size=3),
        max_leaves=8,
    ),
)


@pytest.mark.slow
@settings(max_examples=1000, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(msg=messages)
def test_random_messages_get_replies_and_touch_nothing_outside(served, msg) -> None:
    client, root, outside = served
    with client.websocket_connect(f"/ws?token={TOKEN}", headers=HOST) as ws:
        ws.send_text(json.dumps(msg, allow_nan=True))
        reply = json.loads(ws.receive_text())
        assert reply["ok"] in (True, False) and (reply["ok"] or reply["error"])
        ws.send_text('{"op": "state", "id": "alive"}')
        assert json.loads(ws.receive_text())["ok"]
    assert list(outside.iterdir()) == []
    for dirpath, _, files in os.walk(root):
        for f in files:
            assert Path(dirpath, f).resolve().is_relative_to(root.resolve())


@settings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(msg=messages)
def test_random_messages_quick(served, msg) -> None:
    """The same property on 40 messages in the default suite (the 1,000 run under -m slow)."""
    test_random_messages_get_replies_and_touch_nothing_outside.hypothesis.inner_test(served, msg)


def test_malformed_frames(served) -> None:
    client, _, _ = served
    with client.websocket_connect(f"/ws?token={TOKEN}", headers=HOST) as ws:
        for text in ("{", "[]", "null", '{"op": "drag", "x": 1e999}', "x" * 2_000_000, "[" * 100_000):
            ws.send_text(text)
            assert json.loads(ws.receive_text())["ok"] is False
        ws.send_text('{"op": "state"}')
        assert json.loads(ws.receive_text())["ok"]


def test_the_viewer_page_is_the_runs_page(served) -> None:
    """/view: the run as `vloop view` writes it (every sample of the file's grid), behind the same token."""
    client, _, _ = served
    with client.websocket_connect(f"/ws?token={TOKEN}", headers=HOST) as ws:  # the random messages may have left any
        ws.send_text(json.dumps({"op": "open", "catalog": "fourbar_textbook_example"}))
        assert json.loads(ws.receive_text())["ok"]
    assert client.get("/view", headers=HOST).status_code == 403
    page = client.get(f"/view?token={TOKEN}", headers=HOST)
    assert page.status_code == 200 and 'id="vloop-data"' in page.text and '"samples":201' in page.text
