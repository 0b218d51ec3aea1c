"""The console's connected pages: who commands, and what each page is sent.

`Hub` keeps one `Page` per open WebSocket. Messages (JSON) and video frames (JPEG) are published from
any thread (the loop's, the camera's, the monitor's) and handed to the server's event loop; each page
has its own sender, which sends every message in order and, for the video, only the newest frame, and
only while the page keeps up (it says `frame_drawn` after each): a slow page skips frames, it never
builds a backlog or slows another page.

`CommandSeat` is the lock of the issue: the first page to open takes it and commands, every other page
watches; the seat is free again when its page disconnects (and another page may take it).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import json
import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

log = logging.getLogger(__name__)

MAX_QUEUED_MESSAGES = 512
"""A page this far behind on messages is closed (it would otherwise grow the server's memory)."""
FRAMES_IN_FLIGHT = 2
"""Frames sent to a page before it says it drew one: a page that draws slowly gets fewer frames, never a
queue of old ones (the camera-to-page latency stays a frame or two, whatever the page's speed)."""
DRAWN_TIMEOUT_S = 2.0


@dataclass
class Page:
    """One open page (a browser tab's WebSocket): its id, its message queue, its newest frame."""

    page_id: int
    send_text: Callable[[str], Any]
    send_bytes: Callable[[bytes], Any]
    messages: asyncio.Queue[str] = field(default_factory=lambda: asyncio.Queue(MAX_QUEUED_MESSAGES))
    frame: bytes | None = None
    wake: asyncio.Event = field(default_factory=asyncio.Event)
    closed: bool = False
    in_flight: int = 0
    """Frames sent that the page has not said it drew (`frame_drawn`): at most `FRAMES_IN_FLIGHT`."""
    last_sent_s: float = 0.0

    async def run_sender(self) -> None:
        """Send queued messages first, then the newest frame while the page keeps up, until it closes."""
        loop = asyncio.get_running_loop()
        while not self.closed:
            await self.wake.wait()
            self.wake.clear()
            while not self.messages.empty():
                await self.send_text(self.messages.get_nowait())
            if self.in_flight >= FRAMES_IN_FLIGHT and loop.time() - self.last_sent_s > DRAWN_TIMEOUT_S:
                self.in_flight = 0  # a page that stopped saying so (an old script): go on, slowly
            if self.frame is not None and self.in_flight < FRAMES_IN_FLIGHT:
                frame, self.frame = self.frame, None
                self.in_flight += 1
                self.last_sent_s = loop.time()
                await self.send_bytes(frame)

    def drawn(self) -> None:
        """The page drew a frame: room for the next."""
        self.in_flight = max(0, self.in_flight - 1)
        self.wake.set()


class CommandSeat:
    """Which page commands (one at most); thread-safe."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._holder: int | None = None

    @property
    def holder(self) -> int | None:
        with self._lock:
            return self._holder

    def take(self, page_id: int) -> bool:
        """Give the seat to `page_id` if it is free (or already its); True when `page_id` holds it."""
        with self._lock:
            if self._holder is None:
                self._holder = page_id
            return self._holder == page_id

    def release(self, page_id: int) -> bool:
        """Free the seat if `page_id` holds it; True when it did."""
        with self._lock:
            if self._holder != page_id:
                return False
            self._holder = None
            return True


class Hub:
    """Every open page; publishing from any thread once `attach(loop)` has named the server's loop."""

    def __init__(self) -> None:
        self.seat = CommandSeat()
        self._pages: dict[int, Page] = {}
        self._ids = itertools.count(1)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._last: dict[str, str] = {}  # the newest message of each kept type, for a page that joins
        self._lock = threading.Lock()

    def attach(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop

    def new_page_id(self) -> int:
        return next(self._ids)

    # --- pages (server loop only) -------------------------------------------------------------
    def add(self, page: Page) -> None:
        self._pages[page.page_id] = page
        with self._lock:
            kept = list(self._last.values())
        for text in kept:
            self._queue(page, text)

    def remove(self, page: Page) -> None:
        page.closed = True
        page.wake.set()
        self._pages.pop(page.page_id, None)

    def page_count(self) -> int:
        return len(self._pages)

    def _queue(self, page: Page, text: str) -> None:
        try:
            page.messages.put_nowait(text)
        except asyncio.QueueFull:
            log.warning("page %d is %d messages behind: closing it", page.page_id, MAX_QUEUED_MESSAGES)
            self.remove(page)
            return
        page.wake.set()

    def _fan_out(self, text: str, page_id: int | None) -> None:
        for page in list(self._pages.values()):
            if page_id is None or page.page_id == page_id:
                self._queue(page, text)

    def _fan_out_frame(self, frame: bytes) -> None:
        for page in self._pages.values():
            page.frame = frame
            page.wake.set()

    # --- publishing (any thread) --------------------------------------------------------------
    def publish(self, message: dict[str, Any], keep: bool = False, page_id: int | None = None) -> None:
        """Send `message` to every page (or to `page_id` only). `keep`: also give the newest message of
        its type to each page that opens later (the state a new page must show at once)."""
        text = json.dumps(message, separators=(",", ":"), allow_nan=False)
        if keep:
            with self._lock:
                self._last[str(message["type"])] = text
        self._call(self._fan_out, text, page_id)

    def publish_frame(self, frame: bytes) -> None:
        """A video frame (header + JPEG, `controller.console.video`) for every page; older unsent ones
        are dropped."""
        self._call(self._fan_out_frame, frame)

    def _call(self, function: Callable[..., None], *args: Any) -> None:
        loop = self._loop
        if loop is None or loop.is_closed():
            return
        with contextlib.suppress(RuntimeError):  # the loop closed since the check: the server is stopping
            loop.call_soon_threadsafe(function, *args)
