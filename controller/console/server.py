"""The console's web server: Starlette on uvicorn, every request behind the run's token.

Everything lives under `/c/<token>/` (the page, its script and style, the WebSocket, the reports); a
request anywhere else, or with another token, is refused with 403 before it reaches a route, the
WebSocket included (closed before it is accepted). The token is `secrets.token_urlsafe(24)` per run
and compared in constant time; a WebSocket whose Origin is not this server is refused too, so another
site open in the same browser cannot drive the vehicle even from inside the machine.

The page sends small JSON messages (`Inbound`: an instruction, a command, taking the seat); each is
validated, and anything else (bad JSON, an unknown type, a field out of range, a message over
`MAX_MESSAGE_BYTES`) gets one line back on that page and changes nothing. Only the page holding the
`CommandSeat` commands; the others watch. The server runs uvicorn in a thread of its own, so the
caller's thread stays free to stop the flight safely on Ctrl-C.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import secrets
import threading
from collections.abc import Awaitable, Callable, MutableMapping
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal, Protocol
from urllib.parse import urlsplit

import uvicorn
from pydantic import BaseModel, ConfigDict, Field, TypeAdapter, ValidationError
from starlette.applications import Starlette
from starlette.exceptions import HTTPException
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, Response
from starlette.routing import Mount, Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

from controller.console.hub import Hub, Page

log = logging.getLogger(__name__)

MAX_MESSAGE_BYTES = 4096
"""The largest message a page may send (an instruction is a line of text)."""
START_TIMEOUT_S = 10.0
MAX_CONNECTIONS = 64
"""Open connections (pages, requests) at once; more are answered 503 (a flood cannot exhaust the server)."""
FRAME_DRAWN = '{"type":"frame_drawn"}'
"""What the page sends after drawing each frame, exactly (`FrameDrawnMessage`)."""
STATIC_FILES = {"console.js": "text/javascript", "console.css": "text/css"}
REPORT_FILES = ("report.json", "camera.gif", "trajectory.png")
"""What a page may fetch of the session's report folder: the report and its pictures, nothing else."""

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
App = Callable[[Scope, Receive, Send], Awaitable[None]]


class _Inbound(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class InstructionMessage(_Inbound):
    type: Literal["instruction"]
    text: str = Field(max_length=300)


class CommandMessage(_Inbound):
    type: Literal["command"]
    name: Literal["takeoff", "hold", "land", "kill"]
    confirm: bool = False
    """Kill only: the page asked the operator to confirm, and they did."""
    sent_ms: float | None = None
    """The page's clock when the button was pressed (Unix ms), for the Hold benchmark."""


class TakeSeatMessage(_Inbound):
    type: Literal["take_command"]


class FrameDrawnMessage(_Inbound):
    """The page drew a video frame (flow control: `hub.FRAMES_IN_FLIGHT`); any page may say it."""

    type: Literal["frame_drawn"]


Inbound = Annotated[
    InstructionMessage | CommandMessage | TakeSeatMessage | FrameDrawnMessage, Field(discriminator="type")
]
INBOUND = TypeAdapter(Inbound)


class Operator(Protocol):
    """What the server needs of the flight behind it (`controller.console.pilot.Pilot`)."""

    def hello(self) -> dict[str, Any]:
        """What a page needs once, when it opens (vehicle, ε, image size, the move names)."""
        ...

    def instruct(self, text: str) -> str | None:
        """Start centring on `text`; None when it started, else why not (shown on the page)."""
        ...

    def command(self, name: str, sent_ms: float | None) -> str | None:
        """Take off, Hold, Land or Kill, handed to a thread of the operator's (it must not block); None
        when sent, else why not."""
        ...

    def commander_left(self) -> None:
        """The commanding page closed (mid-centring: hold)."""
        ...

    def report_dir(self) -> Path:
        """The session's report folder (report.json: the page links each instruction's entry in it)."""
        ...


def new_token() -> str:
    return secrets.token_urlsafe(24)


def _static_text(name: str) -> str:
    return resources.files("controller.console").joinpath("static").joinpath(name).read_text(encoding="utf-8")


class TokenGate:
    """ASGI middleware: only `/c/<token>/...` passes; anything else is refused before routing."""

    def __init__(self, app: App, token: str) -> None:
        self.app = app
        self.prefix = f"/c/{token}"

    def _allowed(self, scope: Scope) -> bool:
        path = str(scope.get("path", ""))
        head, sep, _ = path[len("/c/") :].partition("/") if path.startswith("/c/") else ("", "", "")
        token_ok = secrets.compare_digest(f"/c/{head}".encode(), self.prefix.encode()) and bool(sep)
        return token_ok and (scope["type"] != "websocket" or _same_origin(scope))

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket") or self._allowed(scope):
            await self.app(scope, receive, send)
            return
        if scope["type"] == "websocket":
            await send({"type": "websocket.close", "code": 4403})  # before accept: an HTTP 403
            return
        await Response("403: this console needs the address it printed (with its token)\n", 403)(
            scope, receive, send
        )


def _same_origin(scope: Scope) -> bool:
    """A WebSocket from this server's own page: no Origin (not a browser) or one naming this host."""
    headers = dict(scope.get("headers") or [])
    origin = headers.get(b"origin")
    if origin is None:
        return True
    host = headers.get(b"host", b"").decode("latin-1")
    return urlsplit(origin.decode("latin-1")).netloc == host


def create_app(token: str, hub: Hub, operator: Operator) -> App:
    """The console as an ASGI app: the page, its files, the WebSocket and the reports, under the token."""

    async def page(request: Request) -> Response:
        return HTMLResponse(_static_text("index.html"), headers={"Cache-Control": "no-store"})

    async def static(request: Request) -> Response:
        name = request.path_params["name"]
        if name not in STATIC_FILES:
            raise HTTPException(404)
        return Response(_static_text(name), media_type=STATIC_FILES[name])

    async def report(request: Request) -> Response:
        name = request.path_params["name"]
        path = operator.report_dir() / name
        if name not in REPORT_FILES or not path.is_file():
            raise HTTPException(404)
        return FileResponse(path, headers={"Cache-Control": "no-store"})

    async def instruction(request: Request) -> Response:
        """One instruction's entry of report.json (the page's log links each instruction here)."""
        number = request.path_params["number"]
        try:
            entries = json.loads((operator.report_dir() / "report.json").read_text())["instructions"]
            entry = entries[number - 1] if number >= 1 else None
        except (OSError, ValueError, KeyError, IndexError, TypeError):
            entry = None
        if not isinstance(entry, dict):
            raise HTTPException(404)
        return JSONResponse(entry, headers={"Cache-Control": "no-store"})

    async def socket(websocket: WebSocket) -> None:
        await _serve_page(websocket, hub, operator)

    routes = [
        Route("/", page),
        Route("/static/{name}", static),
        Route("/reports/instructions/{number:int}", instruction),
        Route("/reports/{name}", report),
        WebSocketRoute("/ws", socket),
    ]
    app = Starlette(routes=[Mount(f"/c/{token}", routes=routes)])
    return TokenGate(app, token)


async def _serve_page(websocket: WebSocket, hub: Hub, operator: Operator) -> None:
    """One page: hello, then its messages in, until it closes; the seat freed (and a hold) if it led."""
    await websocket.accept()
    page = Page(hub.new_page_id(), websocket.send_text, websocket.send_bytes)
    commands = hub.seat.take(page.page_id)
    hub.add(page)
    hub.publish({"type": "hello", **operator.hello(), "page": page.page_id}, page_id=page.page_id)
    _say_seat(hub)
    sender = asyncio.create_task(page.run_sender())
    try:
        while True:
            text = await websocket.receive_text()
            if text == FRAME_DRAWN:  # the most frequent message, answered without parsing
                page.drawn()
                continue
            reply = await _handle(text, page, hub, operator)
            if reply is not None:
                hub.publish({"type": "message", "level": "warning", "text": reply}, page_id=page.page_id)
    except (WebSocketDisconnect, RuntimeError, KeyError):  # closed, or sent bytes where text was expected
        pass
    finally:
        hub.remove(page)
        sender.cancel()
        with contextlib.suppress(asyncio.CancelledError, Exception):
            await sender
        if hub.seat.release(page.page_id):
            log.info("the commanding page %d closed", page.page_id)
            await asyncio.to_thread(operator.commander_left)
        _say_seat(hub)
    del commands


def _say_seat(hub: Hub) -> None:
    hub.publish({"type": "seat", "holder": hub.seat.holder, "pages": hub.page_count()}, keep=True)


async def _handle(text: str, page: Page, hub: Hub, operator: Operator) -> str | None:
    """One message from a page; the line to show it when the message is refused, else None."""
    page_id = page.page_id
    if len(text.encode()) > MAX_MESSAGE_BYTES:
        return f"message refused: over {MAX_MESSAGE_BYTES} bytes"
    try:
        message = INBOUND.validate_json(text)
    except ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(p) for p in first["loc"]) or "message"
        return f"message refused: {where}: {first['msg']}"
    if isinstance(message, FrameDrawnMessage):
        page.drawn()
        return None
    if isinstance(message, TakeSeatMessage):
        if not hub.seat.take(page_id):
            return "another page commands; this one watches (it may take the seat when that page closes)"
        _say_seat(hub)
        return None
    if hub.seat.holder != page_id:
        return "this page watches: another page commands (take the seat when it is free)"
    if isinstance(message, InstructionMessage):
        return await asyncio.to_thread(operator.instruct, message.text)
    if message.name == "kill" and not message.confirm:
        return "Kill stops the motors in the air: confirm it"
    return operator.command(message.name, message.sent_ms)  # it only hands the command to its own thread


class ConsoleServer:
    """uvicorn serving `app` on `host:port` (0: a free port) in a thread; `url` once started."""

    def __init__(self, app: App, hub: Hub, token: str, host: str = "127.0.0.1", port: int = 0) -> None:
        self.hub = hub
        self.token = token
        self.host = host
        config = uvicorn.Config(
            app, host=host, port=port, log_level="warning", ws_max_size=MAX_MESSAGE_BYTES * 4,
            lifespan="off", access_log=False, limit_concurrency=MAX_CONNECTIONS,
        )  # fmt: skip
        self._server = uvicorn.Server(config)
        self._thread = threading.Thread(target=self._run, name="console-server", daemon=True)
        self._failure: BaseException | None = None
        self.port = port

    def _run(self) -> None:
        try:
            asyncio.run(self._serve())
        except BaseException as exc:  # said by start()
            self._failure = exc

    async def _serve(self) -> None:
        self.hub.attach(asyncio.get_running_loop())
        await self._server.serve()

    def start(self) -> str:
        """Serve; the page's address (with its token). `OSError` when the address cannot be bound."""
        self._thread.start()
        waited = 0.0
        while not self._server.started:
            if self._failure is not None or not self._thread.is_alive():
                raise OSError(f"the console could not serve on {self.host}:{self.port}: {self._failure}")
            if waited > START_TIMEOUT_S:
                raise OSError(f"the console did not start serving within {START_TIMEOUT_S:g} s")
            self._thread.join(0.02)
            waited += 0.02
        sockets = [s for server in self._server.servers for s in server.sockets]
        self.port = sockets[0].getsockname()[1]
        return self.url

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"http://{host}:{self.port}/c/{self.token}/"

    def close(self, timeout_s: float = 5.0) -> None:
        self._server.should_exit = True
        if self._thread.is_alive():
            self._thread.join(timeout_s)
