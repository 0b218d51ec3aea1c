"""The console's server on its own, over real HTTP and a real WebSocket on loopback: the token, the
command seat, refusing bad messages, the report files a page may fetch.

The flight behind it is `FakeOperator` (a stand-in that records what reached it): these tests are about
the server code around the operator; the flying console is tested in test_console_browser.py.
"""

from __future__ import annotations

import json
import time
import urllib.error
import urllib.request
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import ClientConnection, connect

from controller.console.hub import Hub
from controller.console.server import ConsoleServer, create_app, new_token


class FakeOperator:
    """Records instructions and commands; refuses an instruction that says 'refuse'."""

    def __init__(self, report_root: Path) -> None:
        self.root = report_root
        self.instructions: list[str] = []
        self.commands: list[str] = []
        self.left = 0

    def hello(self) -> dict[str, Any]:
        return {"vehicle": "fake", "epsilon_px": 10.0, "actions": []}

    def instruct(self, text: str) -> str | None:
        self.instructions.append(text)
        return "refused: no such target" if "refuse" in text else None

    def command(self, name: str, sent_ms: float | None) -> str | None:
        self.commands.append(name)
        return None

    def commander_left(self) -> None:
        self.left += 1

    def report_dir(self) -> Path:
        return self.root


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory):
    root = tmp_path_factory.mktemp("session")
    entry = {"instruction": "centre the gauge", "outcome": "centred"}
    report = {"outcome": "centred", "instructions": [entry]}
    (root / "report.json").write_text(json.dumps(report))
    (root / "secret.txt").write_text("not for pages")
    (root / "sub").mkdir()
    (root / "sub" / "report.json").write_text("{}")
    operator = FakeOperator(root)
    hub = Hub()
    token = new_token()
    server = ConsoleServer(create_app(token, hub, operator), hub, token)
    url = server.start()
    yield url, token, operator, server
    server.close()


def _get(url: str) -> tuple[int, bytes]:
    try:
        with urllib.request.urlopen(url, timeout=5) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read()


def _wrong(token: str) -> str:
    """The token with its last character changed (to one it is not: a random token may end in any)."""
    return token[:-1] + ("y" if token[-1] != "y" else "z")


def _ws(url: str, **kwargs: Any) -> ClientConnection:
    return connect(url.replace("http://", "ws://") + "ws", open_timeout=5, **kwargs)


def _until(
    ws: ClientConnection, kind: str, where: Callable[[dict[str, Any]], bool] = bool, timeout_s: float = 5.0
) -> dict[str, Any]:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        message = ws.recv(timeout=max(0.01, deadline - time.monotonic()))
        if isinstance(message, str):
            data = json.loads(message)
            if data["type"] == kind and where(data):
                return data
    raise AssertionError(f"no {kind!r} message within {timeout_s} s")


def test_the_page_and_its_files_need_the_token(served) -> None:
    url, token, _, server = served
    assert url == f"http://127.0.0.1:{server.port}/c/{token}/"
    status, body = _get(url)
    assert status == 200 and b"dronectl console" in body
    assert _get(url + "static/console.js")[0] == 200
    base = f"http://127.0.0.1:{server.port}"
    wrong = _wrong(token)
    for refused in ("/", "/c/", f"/c/{token}", f"/c/{wrong}/", f"/c/{wrong}/static/console.js",
                    "/static/console.js", f"/c/x/{token}/"):  # fmt: skip
        assert _get(base + refused)[0] == 403, refused


def test_a_websocket_without_the_token_or_from_another_site_is_refused(served) -> None:
    url, token, operator, server = served
    with pytest.raises(InvalidStatus) as refused:
        connect(f"ws://127.0.0.1:{server.port}/c/{_wrong(token)}/ws", open_timeout=5)
    assert refused.value.response.status_code == 403
    with pytest.raises(InvalidStatus):
        _ws(url, origin="http://evil.example")  # type: ignore[arg-type]
    assert operator.commands == [] and operator.instructions == []


def test_one_page_commands_the_others_watch_and_the_seat_frees_on_close(served) -> None:
    url, _, operator, _ = served
    first = _ws(url)
    hello = _until(first, "hello")
    second = _ws(url)
    hello2 = _until(second, "hello")
    seat = _until(second, "seat")
    assert seat["holder"] == hello["page"] != hello2["page"]
    second.send(json.dumps({"type": "command", "name": "hold"}))
    assert "watches" in _until(second, "message")["text"]
    assert operator.commands == []
    first.send(json.dumps({"type": "command", "name": "hold"}))
    first.send(json.dumps({"type": "instruction", "text": "refuse the flux capacitor"}))
    assert _until(first, "message")["text"] == "refused: no such target"
    assert operator.commands == ["hold"]
    first.close()
    deadline = time.monotonic() + 5
    while operator.left == 0 and time.monotonic() < deadline:
        time.sleep(0.02)
    assert operator.left == 1  # the commanding page's close reached the operator (who holds)
    second.send(json.dumps({"type": "take_command"}))
    assert _until(second, "seat", lambda m: m["holder"] is not None)["holder"] == hello2["page"]
    second.send(json.dumps({"type": "command", "name": "land"}))
    deadline = time.monotonic() + 5
    while operator.commands[-1:] != ["land"] and time.monotonic() < deadline:
        time.sleep(0.02)
    assert operator.commands == ["hold", "land"]
    second.close()


@pytest.mark.parametrize(
    ("message", "said"),
    [
        ("not json", "message refused"),
        (json.dumps({"type": "fly", "to": "the moon"}), "message refused"),
        (json.dumps({"type": "command", "name": "self-destruct"}), "message refused: command.name"),
        (json.dumps({"type": "instruction", "text": "x" * 301}), "message refused: instruction.text"),
        (json.dumps({"type": "instruction", "text": "x" * 5000}), "over 4096 bytes"),
        (json.dumps({"type": "command", "name": "kill"}), "confirm"),
    ],
)
def test_bad_messages_get_one_line_and_change_nothing(served, message: str, said: str) -> None:
    url, _, operator, _ = served
    before = (list(operator.commands), list(operator.instructions))
    with _ws(url) as ws:
        _until(ws, "hello")
        ws.send(message)
        assert said in _until(ws, "message")["text"]
        ws.send(b"\x00\x01binary")  # bytes where text is expected: the page is closed, the server lives
    with _ws(url) as ws:
        assert _until(ws, "hello")["vehicle"] == "fake"
    assert (operator.commands, operator.instructions) == before


def test_a_page_gets_frames_only_as_fast_as_it_draws_them(served) -> None:
    url, _, _, server = served
    with _ws(url) as ws:
        _until(ws, "hello")
        for n in range(6):  # six frames published, the page drawing none
            server.hub.publish_frame(b"frame %d" % n)
            time.sleep(0.05)
        got = []
        deadline = time.monotonic() + 1.0
        while time.monotonic() < deadline:
            try:
                message = ws.recv(timeout=0.1)
            except TimeoutError:
                continue
            if isinstance(message, bytes):
                got.append(message)
        assert got == [b"frame 0", b"frame 1"]  # two in flight, no queue of old ones behind them
        ws.send('{"type":"frame_drawn"}')
        assert ws.recv(timeout=2) == b"frame 5"  # then the newest, not the next in line


def test_a_page_fetches_the_report_and_each_instruction_and_nothing_else(served) -> None:
    url, _, _, _ = served
    status, body = _get(url + "reports/report.json")
    assert status == 200 and json.loads(body)["outcome"] == "centred"
    status, body = _get(url + "reports/instructions/1")
    assert status == 200 and json.loads(body) == {"instruction": "centre the gauge", "outcome": "centred"}
    for name in ("reports/instructions/2", "reports/instructions/0", "reports/instructions/-1",
                 "reports/camera.gif", "reports/secret.txt", "reports/../secret.txt",
                 "reports/sub/report.json",
                 "reports/%2e%2e/secret.txt", "reports/%2Fetc%2Fpasswd"):  # fmt: skip
        assert _get(url + name)[0] in (403, 404), name
