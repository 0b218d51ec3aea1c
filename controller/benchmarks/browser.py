"""A real browser for the console's benchmark and tests: Debian's Chromium driven by Playwright (the
`playwright` package, an optional dependency of the tests), never a browser Playwright downloads.

`chromium_missing()` says why the browser tests must skip (no /usr/bin/chromium, no playwright);
`open_browser()` launches it headless with the flags that work on this machine and a fresh profile.
"""

from __future__ import annotations

import shutil
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
    "--disable-background-networking", "--disable-component-update", "--disable-sync",
]  # fmt: skip


def chromium_missing() -> str | None:
    """Why a browser test cannot run here, or None."""
    if not CHROMIUM.exists():
        return f"no Chromium at {CHROMIUM} (`apt-get install chromium`; .ci/run installs it as root)"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "the playwright package is not installed (pip install -e '.[test]')"
    return None


@contextmanager
def open_browser() -> Iterator[Any]:
    """A headless Chromium (Playwright's `BrowserContext`, a fresh --user-data-dir), closed on exit."""
    from playwright.sync_api import sync_playwright

    profile = Path(tempfile.mkdtemp(prefix="console-chromium-"))
    try:
        with sync_playwright() as playwright:
            context = playwright.chromium.launch_persistent_context(
                str(profile), executable_path=str(CHROMIUM), headless=True, args=FLAGS,
                viewport={"width": 1280, "height": 1000},
            )  # fmt: skip
            try:
                yield context
            finally:
                context.close()
    finally:
        shutil.rmtree(profile, ignore_errors=True)


def until(what: str, check: Callable[[], Any], timeout_s: float, poll_s: float = 0.05) -> Any:
    """Poll `check` until it returns something true (returned), or raise `TimeoutError` naming `what`:
    how the console's benchmark and its browser tests wait for the page."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(poll_s)
    raise TimeoutError(f"not within {timeout_s:g} s: {what}")
