"""The operator's seat behind the page: one flight session, run one operation at a time, with a command
path of its own.

Threads, and why:
- an **operation** thread per operation (take off, centre one instruction): the session's
  `take_off()` / `centre()` block for as long as they fly;
- the **command path** (`command()`): Hold, Land and Kill run at once in threads of their own, never
  behind an operation: the session's interrupt stops the running operation (at its next vehicle call)
  and commands the vehicle;
- the **monitor** (5 Hz): telemetry, the link and the video for the page; a link or video lost while an
  operation runs stops it and holds;
- the **watcher** (4 Hz, while no loop runs): the detector on the newest frame, so the operator sees
  what is in view before naming it (the loop's own steps show it while it runs).

Instructions are understood before anything moves (`grounding.understand`, the words `fly
--instruction` refuses, in the same words), and one that would not say which target it means among
those in view (two valves and "centre the valve"; "centre it" before two targets) is refused as
ambiguous. Everything the page is told goes through `Hub.publish`.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

from controller.console.hub import Hub
from controller.console.views import ACTION_NAMES, detections_view, step_view, telemetry_view
from controller.missions.session import Phase
from controller.planning.grounding import InstructionRefused, TargetQuery
from controller.planning.loop_records import StepRecord
from flight.errors import LinkLostError
from flight.types import Telemetry
from flight.vehicle import Vehicle
from perception.camera_tap import CameraTap
from perception.detector import Detector, detect_all
from perception.types import Detection

log = logging.getLogger(__name__)

TELEMETRY_PERIOD_S = 0.2
WATCH_PERIOD_S = 0.25
VIDEO_LOST_S = 2.0
"""No frame for this long: the video is lost (the page says so, a running operation holds). Two seconds:
a loaded machine's stream stalls for a second now and then (seen at a load average of 22 on 2 cores),
and the loop itself gives up on a camera only after its frame timeout (5 s)."""
JOIN_TIMEOUT_S = 10.0
UNWIND_WAIT_S = 3.0
"""How long an instruction waits for an operation that a Hold has stopped to finish unwinding."""
GROUNDED = (Phase.ON_GROUND, Phase.LANDED, Phase.KILLED)
"""The session's phases in which Hold and Land have nothing to do."""


class Session(Protocol):
    """What the console needs of a flight session (`controller.missions.session.FlightSession`)."""

    @property
    def vehicle(self) -> Vehicle: ...

    @property
    def detector(self) -> Detector: ...

    @property
    def epsilon_px(self) -> float: ...

    @property
    def phase(self) -> Phase: ...

    def telemetry(self) -> Telemetry | None: ...

    def understand(self, instruction: str) -> TargetQuery: ...

    def take_off(self) -> None: ...

    def centre(self, instruction: str, *, on_step: Callable[[StepRecord], None] | None = None) -> Any: ...

    def hold(self) -> None: ...

    def land(self) -> None: ...

    def kill(self) -> None: ...


@dataclass
class LogEntry:
    """One instruction as the page's log shows it."""

    number: int
    instruction: str
    outcome: str | None = None
    steps: int | None = None
    message: str = ""
    report: str | None = None
    """Its entry of the session's report.json, as an address relative to the page, once it ended."""


def ambiguity(text: str, query: TargetQuery, seen: Sequence[Detection]) -> str | None:
    """Why `query` cannot say which of the targets in view it means, or None: several detections fit
    it and they differ (two valves, "centre the valve"; any two targets, "centre it")."""
    fitting = [d for d in seen if query.matches(d)]
    if len(fitting) < 2:
        return None
    if query.kind is None:
        kinds = ", ".join(sorted({f"{d.attribute + ' ' if d.attribute else ''}{d.kind}" for d in fitting}))
        return f"{text.strip()!r} is ambiguous: {len(fitting)} targets in view ({kinds}); name one"
    colours = sorted({d.attribute for d in fitting if d.attribute})
    if len(colours) < 2:
        return None  # one target seen twice, or colours not read: the loop takes the strongest
    return (
        f"{text.strip()!r} is ambiguous: {len(fitting)} {query.describe()}s in view ({', '.join(colours)}); "
        f"say which, e.g. 'centre the {colours[0]} {query.kind}'"
    )


def setpoint_age_s(vehicle: Vehicle) -> float | None:
    """Seconds since the controller's last velocity setpoint, from the `SafeVehicle` in `vehicle`'s
    wrappers; None when none is there or it is not streaming setpoints (not in offboard)."""
    while vehicle is not None:
        age = getattr(vehicle, "setpoint_age_s", None)
        if callable(age):
            return age()
        vehicle = getattr(vehicle, "inner", None)
    return None


class Pilot:
    """One session flown from the page (see the module docstring). `report_root`: the session's folder."""

    def __init__(
        self,
        session: Session,
        tap: CameraTap,
        hub: Hub,
        report_root: Path,
        vehicle_name: str,
        live_telemetry: bool = False,
    ) -> None:
        """`live_telemetry`: read the vehicle itself from the monitor even while an operation runs (a paced
        in-process world, safe from any thread); else `session.telemetry()`, as the session allows."""
        self.session = session
        self.live_telemetry = live_telemetry
        self.tap = tap
        self.hub = hub
        self.report_root = report_root
        self.vehicle_name = vehicle_name
        self.log_entries: list[LogEntry] = []
        self._lock = threading.Lock()
        self._operation: threading.Thread | None = None
        self._activity = "idle"
        self._instruction: str | None = None
        self._closing = threading.Event()
        self._seen: tuple[Detection, ...] = ()
        self._link = "ok"
        self._video = "ok"
        self._phase = session.phase
        self._commands = ThreadPoolExecutor(max_workers=3, thread_name_prefix="console-command")
        self.command_log: list[dict[str, Any]] = []
        """Every Hold / Land / Kill: its name and, in Unix seconds, when the page's button was pressed
        (`pressed_s`, the page's clock), when its thread began (`started_s`) and when the session's call
        returned (`done_s`)."""
        self._threads = [
            threading.Thread(target=self._monitor, name="console-monitor", daemon=True),
            threading.Thread(target=self._watch, name="console-watcher", daemon=True),
        ]

    def start(self) -> None:
        for thread in self._threads:
            thread.start()
        self._publish_state()
        self._publish_log()

    # --- what the server asks (`controller.console.server.Operator`) ---------------------------
    def hello(self) -> dict[str, Any]:
        return {
            "vehicle": self.vehicle_name,
            "epsilon_px": self.session.epsilon_px,
            "actions": list(ACTION_NAMES),
            "video_lost_s": VIDEO_LOST_S,
        }

    def report_dir(self) -> Path:
        return self.report_root

    def instruct(self, text: str) -> str | None:
        """Centre on `text` (see the module docstring); None when the loop started, else why not."""
        try:
            query = self.session.understand(text)
        except InstructionRefused as exc:
            return str(exc)
        with self._lock:
            seen = self._seen
        refused = ambiguity(text, query, seen)
        if refused is not None:
            return refused
        if not self._flying():
            return f"the vehicle is {self.session.phase.value.replace('_', ' ')}: press Take off first"
        with self._lock:
            operation = self._operation
        if operation is not None and self.session.phase is Phase.HOLDING:
            operation.join(UNWIND_WAIT_S)  # one a Hold stopped is still unwinding: the next may follow it
        return self._start("centring", text, lambda: self._centre(text, query))

    def command(self, name: str, sent_ms: float | None = None) -> str | None:
        """Take off (an operation), or Hold / Land / Kill (the command path: at once, whatever runs: the
        session stops the running operation and commands the vehicle)."""
        if name == "takeoff":
            if self._flying():
                return "already flying"
            return self._start("taking off", None, self._take_off)
        if name not in ("hold", "land", "kill"):
            return f"unknown command {name!r}"
        if name in ("hold", "land") and self.session.phase in GROUNDED:
            return f"{name.capitalize()}: the vehicle is {self.session.phase.value.replace('_', ' ')}"
        record = {"name": name, "pressed_s": None if sent_ms is None else sent_ms / 1000.0}
        self._commands.submit(self._run_command, name, record)
        return None

    def commander_left(self) -> None:
        """The commanding page closed: whatever runs stops and the vehicle holds."""
        with self._lock:
            running = self._operation is not None
        if running:
            self._say("the commanding page closed: holding", "warning")
            self.command("hold")

    @property
    def busy(self) -> bool:
        """Whether an operation (take off, centre) is running."""
        with self._lock:
            return self._operation is not None

    # --- operations ---------------------------------------------------------------------------
    def _start(self, activity: str, instruction: str | None, job: Callable[[], None]) -> str | None:
        with self._lock:
            if self._closing.is_set():
                return "the console is closing"
            if self._operation is not None:
                what = f"{self._activity}: {self._instruction}" if self._instruction else self._activity
                return f"busy ({what}); wait for it to end, or press Hold"
            self._activity, self._instruction = activity, instruction
            self._operation = threading.Thread(
                target=self._run_operation, args=(job,), name=f"console-{activity}", daemon=True
            )
            self._operation.start()
        self._publish_state()
        return None

    def _run_operation(self, job: Callable[[], None]) -> None:
        try:
            job()
        except Exception as exc:
            log.error("console: %s failed: %s", self._activity, exc)
            self._say(f"{self._activity} failed: {exc}", "error")
        finally:
            with self._lock:
                self._operation = None
                self._activity, self._instruction = "idle", None
            self._publish_state()

    def _take_off(self) -> None:
        self.session.take_off()
        if self.session.phase is Phase.HOLDING:
            self._say("took off: the vehicle holds; type an instruction", "info")

    def _centre(self, text: str, query: TargetQuery) -> None:
        entry = LogEntry(len(self.log_entries) + 1, text)
        self.log_entries.append(entry)
        self._publish_log()
        on_step = self._on_step(entry, query)
        try:
            result = self.session.centre(text, on_step=on_step)
        except InstructionRefused as exc:  # the session's own check (words of the scene)
            entry.outcome, entry.message = "refused", str(exc)
            self._say(str(exc), "warning")
        except Exception as exc:
            entry.outcome, entry.message = "error", f"{type(exc).__name__}: {exc}"
            raise
        else:
            entry.outcome, entry.message, entry.steps = result.outcome.value, result.message, result.steps
            entry.report = f"reports/instructions/{result.index}"
        finally:
            self._publish_log()

    def _on_step(self, entry: LogEntry, query: TargetQuery) -> Callable[[StepRecord], None]:
        def on_step(step: StepRecord) -> None:
            with self._lock:
                self._seen = step.detections
            self.hub.publish(step_view(step, entry.instruction, query, self.session.epsilon_px, entry.number))

        return on_step

    # --- the command path ---------------------------------------------------------------------
    def _run_command(self, name: str, record: dict[str, Any]) -> None:
        record["started_s"] = time.time()
        self.command_log.append(record)
        action = {"hold": self.session.hold, "land": self.session.land, "kill": self.session.kill}[name]
        try:
            action()
        except Exception as exc:
            log.error("console: %s failed: %s", name, exc)
            self._say(f"{name.capitalize()} failed: {exc}", "error")
            return
        finally:
            record["done_s"] = time.time()
        done = {"hold": "the vehicle holds", "land": "landed", "kill": "motors stopped"}[name]
        self._say(f"{name.capitalize()}: {done} ({record['done_s'] - record['started_s']:.2f} s)", "info")

    # --- monitor and watcher ------------------------------------------------------------------
    def _flying(self) -> bool:
        return self.session.phase not in GROUNDED

    def _monitor(self) -> None:
        while not self._closing.wait(TELEMETRY_PERIOD_S):
            try:
                vehicle = self.session.vehicle  # simulated clock, operation running: the session's copy
                live = self.live_telemetry or vehicle.realtime
                telemetry = vehicle.telemetry() if live else self.session.telemetry()
                link = "ok"
            except LinkLostError:
                telemetry, link = None, "lost"
            except Exception as exc:  # the page must keep its monitor whatever the vehicle does
                log.debug("console monitor: telemetry failed: %s", exc)
                telemetry, link = None, "lost"
            video = "lost" if self.tap.failure is not None or self.tap.silent_s() > VIDEO_LOST_S else "ok"
            self.hub.publish(telemetry_view(telemetry, setpoint_age_s(self.session.vehicle), link), keep=True)
            phase = self.session.phase
            changed = (link, video, phase) != (self._link, self._video, self._phase)
            self._phase = phase
            lost = [what for what, now, before in (("link", link, self._link), ("video", video, self._video))
                    if now == "lost" and before == "ok"]  # fmt: skip
            self._link, self._video = link, video
            if changed:
                self._publish_state()
            for what in lost:
                self._on_lost(what)

    def _on_lost(self, what: str) -> None:
        with self._lock:
            running = self._operation is not None
        self._say(f"{what} lost" + (": holding" if running else ""), "error")
        if running:
            self.command("hold")

    def _watch(self) -> None:
        last = -1
        while not self._closing.wait(WATCH_PERIOD_S):
            with self._lock:
                centring = self._activity == "centring"
            frame = self.tap.latest()
            if centring or frame is None or frame.frame_number == last:
                continue
            last = frame.frame_number
            try:
                detections = detect_all(self.session.detector, frame.image)
            except Exception as exc:
                log.warning("console watcher: the detector failed: %s", exc)
                continue
            with self._lock:
                self._seen = detections
            self.hub.publish(
                {
                    "type": "detections",
                    "frame": frame.frame_number,
                    "frame_size": [frame.width, frame.height],
                    "epsilon_px": self.session.epsilon_px,
                    "detections": detections_view(detections, None),
                }
            )

    # --- what the page is told ----------------------------------------------------------------
    def _say(self, text: str, level: str) -> None:
        self.hub.publish({"type": "message", "level": level, "text": text})

    def _publish_state(self) -> None:
        with self._lock:
            activity, instruction = self._activity, self._instruction
        self.hub.publish(
            {
                "type": "state",
                "activity": activity,
                "instruction": instruction,
                "flying": self._flying(),
                "phase": self.session.phase.value,
                "video": self._video,
                "link": self._link,
            },
            keep=True,
        )

    def _publish_log(self) -> None:
        self.hub.publish({"type": "log", "entries": [asdict(e) for e in self.log_entries]}, keep=True)

    # --- the end ------------------------------------------------------------------------------
    def close(self) -> None:
        """Stop what runs and the threads (the session, which the caller closes, lands the vehicle)."""
        self._closing.set()
        with self._lock:
            operation = self._operation
        if operation is not None:
            try:
                self.session.hold()
            except Exception as exc:  # the session's own exit still lands it
                log.error("console: could not hold on closing: %s", exc)
            operation.join(JOIN_TIMEOUT_S)
        for thread in self._threads:
            if thread.is_alive():
                thread.join(JOIN_TIMEOUT_S)
        self._commands.shutdown(wait=True, cancel_futures=False)
