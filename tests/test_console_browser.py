"""`dronectl console` in a real browser (Debian's headless Chromium, driven by Playwright) flying the
in-process simulation: the page loads, frames arrive, bad instructions are refused on the page, an
instruction is centred (per the simulator's truth), Hold reaches the vehicle mid-centring, a second tab
only watches, closing the commanding page mid-centring holds, Kill asks to confirm and then stops the
motors. One console and one browser for the whole scenario (the steps depend on each other).

`DRONECTL_CONSOLE_SCREENSHOTS=DIR` also saves the page at each stage as PNGs in DIR (docs/console/
holds the ones docs/console.md shows); CI leaves it unset so the tree stays clean.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import pytest

from controller.benchmarks.browser import chromium_missing, open_browser, until
from controller.console.run import ConsoleOptions, open_console
from controller.missions.schema import load_mission
from flight.types import FlightMode

REPO = Path(__file__).resolve().parents[1]
MISSION = REPO / "missions" / "regression" / "three_targets.yaml"
SHOTS = os.environ.get("DRONECTL_CONSOLE_SCREENSHOTS")

pytestmark = pytest.mark.skipif(chromium_missing() is not None, reason=str(chromium_missing()))


def _shot(page: Any, name: str) -> None:
    if SHOTS:
        Path(SHOTS).mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(Path(SHOTS) / f"{name}.png"), full_page=True)


def _ended(page: Any, number: int) -> str | None:
    """Instruction `number`'s outcome in the page's log, once it has one."""
    cells = page.locator(f'#log tr[data-number="{number}"] td')
    outcome = cells.nth(2).text_content() if cells.count() > 2 else None
    return None if outcome in (None, "running") else outcome


def _messages(page: Any) -> list[str]:
    return [m["text"] for m in page.evaluate("window.consoleStats.messages")]


@pytest.mark.timeout(420)
def test_the_console_in_a_browser(tmp_path: Path) -> None:
    mission = load_mission(MISSION)
    options = ConsoleOptions(mission, tmp_path / "session", sim_pace=2.0)
    with open_console(options) as console, open_browser() as browser:
        session = console.session
        page = browser.new_page()
        page.goto(console.url)
        # --- the page loads, video frames arrive, the page commands
        until("video frames on the page", lambda: page.evaluate("window.consoleStats.frames") >= 10, 30)
        until("telemetry on the page", lambda: page.text_content("#t-mode") == "ready", 10)
        assert page.text_content("#seat") == "you command"
        assert page.text_content("#t-link") == "ok"
        # --- bad instructions: a message on the page, no flight
        for text, said in (
            ("", "the instruction is empty"),
            ("centre the flux capacitor", "no known target is called 'flux capacitor'"),
            ("centre the gauge", "the vehicle is on ground: press Take off first"),
        ):
            page.fill("#instruction", text)
            page.press("#instruction", "Enter")
            until(f"the refusal of {text!r}", lambda said=said: any(said in m for m in _messages(page)), 10)
        assert page.locator("#log tbody tr").count() == 0 and session.results == []
        # --- take off, then centre the gauge
        page.click("#btn-takeoff")
        until("airborne and holding", lambda: session.phase.value == "holding", 90)
        _shot(page, "1-airborne")
        page.fill("#instruction", "centre the gauge")
        page.press("#instruction", "Enter")
        until("the first step drawn", lambda: page.evaluate("window.consoleStats.steps") >= 1, 30)
        _shot(page, "2-centring")
        assert page.locator(".bar").count() == 9
        outcome = until("instruction 1 ended", lambda: _ended(page, 1), 120)
        assert outcome == "centred"
        first = session.results[0]
        truth = first.final_truth_offset_px
        assert truth is not None and max(abs(truth[0]), abs(truth[1])) <= session.epsilon_px  # per truth
        report = page.evaluate(
            "async () => (await fetch(document.querySelector('#log tr[data-number=\"1\"] a').href)).json()"
        )
        assert report["instruction"] == "centre the gauge" and report["outcome"] == "centred"
        _shot(page, "3-centred")
        # --- Hold mid-centring reaches the vehicle: HOLD mode in its telemetry, the loop stopped
        others = [t for t in session.kit.info.get("targets", []) if t["kind"] != "gauge"]
        page.fill("#instruction", f"centre the {others[0]['kind']}")
        page.press("#instruction", "Enter")
        until("centring the second", lambda: session.phase.value == "centring", 20)
        page.click("#btn-hold")
        until("HOLD mode", lambda: session.vehicle.telemetry().flight_mode is FlightMode.HOLD, 10)
        until("HOLD on the page", lambda: page.text_content("#t-mode") == "hold", 10)
        assert until("instruction 2 ended", lambda: _ended(page, 2), 30) == "stopped"
        _shot(page, "4-held")
        # --- a second tab watches; closing the commanding page mid-centring holds
        watcher = browser.new_page()
        watcher.goto(console.url)
        until("the second tab watches", lambda: "watching" in (watcher.text_content("#seat") or ""), 10)
        assert watcher.is_disabled("#btn-hold") and watcher.is_disabled("#instruction")
        page.fill("#instruction", f"centre the {others[-1]['kind']}")
        page.press("#instruction", "Enter")
        until("centring the third", lambda: session.phase.value == "centring", 20)
        page.close()
        held = lambda: session.vehicle.telemetry().flight_mode is FlightMode.HOLD  # noqa: E731
        until("held after the page closed", held, 15)
        assert until("instruction 3 ended", lambda: _ended(watcher, 3), 30) == "stopped"
        assert session.vehicle.telemetry().in_air  # held in the air, not landed
        # --- the seat is free: the watcher takes it; Kill asks to confirm, then stops the motors
        until("the seat free", lambda: watcher.is_visible("#take-seat"), 10)
        watcher.click("#take-seat")
        until("the watcher commands", lambda: watcher.text_content("#seat") == "you command", 10)
        watcher.click("#btn-kill")
        assert watcher.is_visible("#kill-confirm")
        watcher.click("#btn-kill-cancel")
        time.sleep(0.5)
        assert session.vehicle.telemetry().armed
        watcher.click("#btn-kill")
        watcher.click("#btn-kill-confirm")
        until("motors stopped", lambda: not session.vehicle.telemetry().armed, 10)
        assert session.phase.value == "killed"
