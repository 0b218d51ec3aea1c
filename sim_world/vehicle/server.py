"""`SimVehicle`: a simulated airframe served as a PX4-flavoured MAVLink 2 vehicle over UDP.

One background thread owns the airframe (`VehicleModel`: the PyBullet `World` in
production, a kinematic fake in unit tests) and runs the loop PX4 SITL runs in
lockstep with its simulator: step the physics to keep up with the wall clock (×
`speed`; with "max", one batch of `max_batch_sim_s` after another, as fast as the thread
goes, serving the link between batches), apply PX4's commander rules, answer every
message, stream telemetry at the requested (wall-clock) rates, and hand the drone's
pose to the camera feed (which renders and serves MJPEG in its own process: see `sim_world.vehicle.video`).

Use in-process (tests) as `with SimVehicle(model, config) as v: ...`, or through
`dronectl sim-vehicle` (`sim_world.vehicle.serve`).

Kept warm between missions, `reset(model, config)` puts a new airframe (a freshly built world) behind
the same link and video server: the loop stops, the commander, parameters and battery start afresh
(an autopilot that has booted: no arming delay), the vehicle's clock (`time_boot_ms`) runs on, and
the loop starts again. Only the world may change; the link's identity (ports, system id, key,
speed, limits) may not.
"""

from __future__ import annotations

import logging
import math
import select
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from types import TracebackType
from typing import Protocol

from pymavlink.dialects.v20 import common as mavlink

from sim_world.vehicle import px4_modes as modes
from sim_world.vehicle.battery import BatteryModel
from sim_world.vehicle.commander import Commander, CommanderConfig
from sim_world.vehicle.commands import MessageHandler
from sim_world.vehicle.config import MAX_SPEED, SimVehicleConfig
from sim_world.vehicle.link import UdpMavlinkLink
from sim_world.vehicle.model import VehicleModel
from sim_world.vehicle.params import ParameterStore, limited_specs
from sim_world.vehicle.px4_modes import Px4Mode
from sim_world.vehicle.telemetry import DEFAULT_RATES_HZ, MessageScheduler, TelemetryBuilder, VehicleSnapshot

log = logging.getLogger(__name__)


class VideoFeed(Protocol):
    """The camera stream beside the vehicle (`sim_world.rendering.video.WorldVideoFeed`)."""

    stream_url: str

    @property
    def truth_url(self) -> str: ...

    @property
    def frames(self) -> int: ...

    @property
    def mean_render_ms(self) -> float: ...

    def start(self) -> None: ...

    def capture(self) -> None:
        """Called by the vehicle loop after each physics batch: take the drone's pose for the next frame."""
        ...

    @property
    def alive(self) -> bool:
        """Whether the render process still runs."""
        ...

    def close(self) -> None: ...


_STATUSTEXT_CHUNK = 50
_MIN_WAIT_S = 0.0005
_MAX_WAIT_S = 0.02


class SimVehicleError(RuntimeError):
    """The vehicle loop failed, or the vehicle was used wrongly (start twice, ...)."""


@dataclass
class LoopStats:
    """What the loop measured; read `SimVehicle.stats()` for a copy."""

    wall_s: float = 0.0
    sim_s: float = 0.0
    iterations: int = 0
    physics_steps: int = 0
    dropped_sim_s: float = 0.0  # time given up because the loop could not keep up
    video_frames: int = 0  # rendered by the video process
    mean_render_ms: float = 0.0
    messages_in: int = 0
    messages_out: int = 0
    messages_unsigned: int = 0  # dropped: no, a wrong or a replayed signature (with a signing key)
    messages_foreign: int = 0  # dropped: from an address that is not the vehicle's controller
    messages_bad: int = 0  # dropped: not MAVLink (CRC, unknown id, garbage)

    @property
    def real_time_factor(self) -> float:
        return self.sim_s / self.wall_s if self.wall_s > 0 else 0.0


class SimVehicle:
    """A `VehicleModel` behind a PX4-like MAVLink endpoint; `start()`/`close()` or a context manager."""

    def __init__(
        self, model: VehicleModel, config: SimVehicleConfig | None = None, video: VideoFeed | None = None
    ):
        self.config = config or SimVehicleConfig()
        self._model = model
        self._video = video
        self._fresh_state(model, self.config.commander)
        self._builder = TelemetryBuilder(self.config.home, uid=0x5157_0000 + self.config.instance)
        self._boot_s = model.time_s
        self._scheduler: MessageScheduler | None = None  # the link's stream rates, kept over resets
        self.reset_clock_s: float | None = None
        """The vehicle's clock (`time_boot_ms`, s) when the last reset's world began (None: never reset)."""
        self._link: UdpMavlinkLink | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._error: BaseException | None = None
        self._stats = LoopStats()
        self._stats_lock = threading.Lock()
        self._snapshot: VehicleSnapshot = self._take_snapshot()
        self._telemetry_failed: set[int] = set()

    def _fresh_state(self, model: VehicleModel, commander: CommanderConfig) -> None:
        """Parameters, commander and battery as a vehicle starts with them."""
        cfg = self.config
        self.params = ParameterStore(limited_specs(cfg.limits), overrides=cfg.params)
        # Faster than real time, the client (MAVSDK: setpoints re-sent at 20 Hz of wall time) is timed
        # on the wall clock: the commander's timers that wait on it use that clock too.
        client_clock = time.monotonic if cfg.faster_than_real_time else None
        self.commander = Commander(model, self.params, commander, client_clock, cfg.limits)
        self._battery = BatteryModel(cfg.battery)

    # ------------------------------------------------------------ lifecycle
    def start(self) -> SimVehicle:
        """Open the UDP endpoint, run the loop in a daemon thread, then start the video feed.

        The loop starts first so heartbeats flow while the render process boots (seconds).
        """
        if self._thread is not None:
            raise SimVehicleError("SimVehicle.start() called twice")
        cfg = self.config
        self._link = UdpMavlinkLink(
            cfg.bind_host,
            cfg.mavlink_local_port,
            (cfg.remote_host, cfg.mavlink_remote_port),
            cfg.system_id,
            1,
            adopt_client=cfg.adopt_client,
            signing_key=cfg.signing_key,
        )
        self._scheduler = MessageScheduler(telemetry_rates_hz(cfg), time.monotonic())
        self._start_loop()
        try:
            if self._video is not None:
                self._video.start()
        except BaseException:
            self.close()
            raise
        log.info(
            "sim vehicle %d: MAVLink sysid %d on udp %s:%d -> %s:%d%s",
            cfg.instance, cfg.system_id, *self._link.local_address, cfg.remote_host, cfg.mavlink_remote_port,
            f", video {self._video.stream_url}" if self._video else "",
        )  # fmt: skip
        return self

    def _start_loop(self) -> None:
        self._stop = threading.Event()
        name = f"sim-vehicle-{self.config.instance}"
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def reset(
        self, model: VehicleModel, config: SimVehicleConfig, while_stopped: Callable[[], None] | None = None
    ) -> None:
        """A new airframe behind the same link (see the module docstring); `while_stopped` runs while the
        loop stands still (the video feed's own reset). `SimVehicleError` if `config` changes more than
        the world's parameters, or the loop had failed."""
        if self._thread is None or self._link is None:
            raise SimVehicleError("SimVehicle.reset() before start()")
        if replace(config, params=self.config.params) != self.config:
            raise SimVehicleError("a reset may change the world and its parameters, not the vehicle's link")
        self._stop.set()
        self._thread.join(5.0)
        if self._thread.is_alive() or self._error is not None:
            raise SimVehicleError(f"the vehicle loop did not stop for a reset: {self._error!r}")
        elapsed_s = self._model.time_s - self._boot_s
        self.reset_clock_s = elapsed_s
        self.config, self._model = config, model
        self._fresh_state(model, replace(config.commander, arming_boot_delay_s=0.0))  # booted long ago
        self._boot_s = model.time_s - elapsed_s  # time_boot_ms runs on: the client's clock of the vehicle
        self._telemetry_failed = set()
        self._snapshot = self._take_snapshot()
        if while_stopped is not None:
            while_stopped()
        self._start_loop()
        log.info("sim vehicle reset: a new world from %.3f s of the vehicle's clock", elapsed_s)

    def close(self, timeout_s: float = 5.0) -> None:
        """Stop the loop and free the ports (idempotent); re-raises a loop failure as SimVehicleError."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            if self._thread.is_alive():
                log.error("sim vehicle loop did not stop within %.1f s", timeout_s)
        if self._video is not None:
            # Safe when the render process already died with us (a process-group SIGTERM from
            # `timeout`, a supervisor or a closing terminal): its stop flag is a lock-free byte.
            self._video.close()
        if self._link is not None:
            self._link.close()
            self._link = None
        stats = self.stats()
        log.info(
            "sim vehicle closed: %.1f s simulated in %.1f s (x%.2f real time), %d video frames (%.1f ms)",
            stats.sim_s, stats.wall_s, stats.real_time_factor, stats.video_frames, stats.mean_render_ms,
        )  # fmt: skip
        if self._error is not None:
            error, self._error = self._error, None
            raise SimVehicleError(f"sim vehicle loop failed: {error!r}") from error

    def __enter__(self) -> SimVehicle:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # -------------------------------------------------------------- queries
    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    @property
    def local_address(self) -> tuple[str, int]:
        if self._link is None:
            raise SimVehicleError("SimVehicle is not started")
        return self._link.local_address

    @property
    def video_url(self) -> str | None:
        return None if self._video is None else self._video.stream_url

    @property
    def truth_url(self) -> str | None:
        return None if self._video is None else self._video.truth_url

    def snapshot(self) -> VehicleSnapshot:
        """The latest state the loop published (thread-safe: an immutable object)."""
        return self._snapshot

    @property
    def mode(self) -> Px4Mode:
        return self._snapshot.mode

    def senders(self) -> dict[str, int]:
        """Messages accepted (so acted on) per sender, as "system/component": who commanded this vehicle."""
        link = self._link
        return {} if link is None else {f"{s}/{c}": n for (s, c), n in sorted(link.senders.items())}

    def stats(self) -> LoopStats:
        with self._stats_lock:
            stats = LoopStats(**vars(self._stats))
        if self._video is not None:
            stats.video_frames, stats.mean_render_ms = self._video.frames, self._video.mean_render_ms
        return stats

    # ----------------------------------------------------------------- loop
    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:
            log.exception("sim vehicle loop failed")
            self._error = exc

    def _loop(self) -> None:
        cfg, model, link, scheduler = self.config, self._model, self._link, self._scheduler
        assert link is not None and scheduler is not None
        dt = 1.0 / model.physics_hz
        handler = MessageHandler(
            self.commander, self.params, scheduler, self._builder, self._take_snapshot,
            cfg.system_id, cfg.home.altitude_amsl_m,
        )  # fmt: skip
        wall0 = start_wall = time.monotonic()
        sim0 = model.time_s
        text_id = 0
        flat_out = cfg.speed == MAX_SPEED
        speed = 1.0 if flat_out else float(cfg.speed)
        max_batch = max(1, round(cfg.max_batch_sim_s * model.physics_hz))
        announce = cfg.faster_than_real_time  # state changes go out at once (`_STATE_MESSAGES`)
        last_state = _state_key(self._snapshot)
        while not self._stop.is_set():
            now = time.monotonic()
            if flat_out:  # 1. physics: one batch, or what the lockstep bound leaves, then serve the link
                limit_s = self._lockstep_limit_s(now)
                steps, dropped = max_batch, 0.0
                if limit_s is not None:
                    steps = min(steps, max(0, int((limit_s - model.time_s) / dt + 1e-9)))
            else:  # 1. physics: catch up with the wall clock (× speed), dropping time after a long stall
                lag_s = sim0 + speed * (now - wall0) - model.time_s
                dropped = max(0.0, lag_s - cfg.max_catch_up_s * speed)
                wall0 += dropped / speed
                steps = int((lag_s - dropped) / dt + 1e-9)
            if steps > 0:
                model.step(steps)
                self._battery.update(steps * dt, self.commander.armed, not model.status().landed)
                if self._video is not None:
                    self._video.capture()
            self.commander.update()
            # 2. messages in, replies to their sender
            for msg, addr in link.receive():
                for reply in handler.handle(msg, link.mav):  # never raises: see MessageHandler.handle
                    link.send_bytes(reply, to=addr)
            # 3. telemetry and status texts to every destination
            due = scheduler.due(now)
            self._snapshot = snap = self._take_snapshot()
            if announce and (state := _state_key(snap)) != last_state:
                last_state = state
                due = sorted(set(due) | set(_STATE_MESSAGES))
            for msg_id in due:
                self._send_telemetry(link, msg_id, snap)
            while self.commander.texts:
                text_id = text_id % 65535 + 1
                for msg in _statustext(*self.commander.texts.popleft(), text_id):
                    link.send(msg)
            with self._stats_lock:
                st = self._stats
                st.iterations += 1
                st.physics_steps += steps
                st.dropped_sim_s += dropped
                st.wall_s = time.monotonic() - start_wall
                st.sim_s = model.time_s - sim0
                ls = link.stats
                st.messages_in, st.messages_out = ls.received, ls.sent
                st.messages_unsigned, st.messages_foreign, st.messages_bad = ls.unsigned, ls.foreign, ls.bad
            # 4. sleep until the next physics step or telemetry is due, or a message arrives
            if flat_out:  # held by the lockstep bound: wait for the client's next setpoint
                select.select([link], [], [], 0.0 if steps else _MIN_WAIT_S * 4)
                continue
            wake = min(wall0 + (model.time_s + dt - sim0) / speed, scheduler.next_due_s())
            select.select([link], [], [], min(max(wake - time.monotonic(), _MIN_WAIT_S), _MAX_WAIT_S))

    def _send_telemetry(self, link: UdpMavlinkLink, msg_id: int, snap: VehicleSnapshot) -> None:
        """One streamed message to every destination; a message that cannot be built is skipped (and said
        once per kind), never the end of the loop."""
        try:
            link.send(self._builder.build(msg_id, snap))
        except Exception as exc:
            if msg_id not in self._telemetry_failed:
                self._telemetry_failed.add(msg_id)
                log.error("telemetry message %d could not be built or sent: %r", msg_id, exc)

    def _lockstep_limit_s(self, now_s: float) -> float | None:
        """Speed "max": in OFFBOARD, the simulated time the vehicle may not pass until the client's next
        setpoint (the last one's + `lockstep_lead_s`); None (free) elsewhere, and once the stream has
        been silent `lockstep_silence_s` of wall time (a stopped client must still meet the failsafe)."""
        last = self.commander.last_setpoint_at() if self.commander.mode == modes.OFFBOARD else None
        if last is None or now_s - last[1] > self.config.lockstep_silence_s:
            return None
        return last[0] + self.config.lockstep_lead_s

    def _take_snapshot(self) -> VehicleSnapshot:
        c, b = self.commander, self._battery
        return VehicleSnapshot(
            time_boot_ms=round((self._model.time_s - self._boot_s) * 1000),
            kinematics=self._model.kinematics(),
            armed=c.armed,
            mode=c.mode,
            system_status=c.system_status,
            landed_state=c.landed_state,
            prearm_ok=c.prearm_ok,
            battery_remaining=b.remaining,
            battery_voltage_v=b.voltage_v,
            battery_current_a=b.current_a,
            battery_consumed_mah=b.consumed_mah,
        )


_CLOCK_STREAMS = (mavlink.MAVLINK_MSG_ID_ATTITUDE, mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED)


def telemetry_rates_hz(config: SimVehicleConfig) -> dict[int, float]:
    """PX4's stream rates (wall clock); faster than real time, ATTITUDE (whose time_boot_ms is a
    client's clock of the vehicle) and LOCAL_POSITION_NED go up with the speed, to at most
    `max_telemetry_hz`, so that a client timing a move on the vehicle's clock stops it within
    about as many simulated milliseconds as at ×1."""
    rates = dict(DEFAULT_RATES_HZ)
    if config.faster_than_real_time:
        factor = math.inf if config.speed == MAX_SPEED else float(config.speed)
        for msg_id in _CLOCK_STREAMS:
            rates[msg_id] = max(rates[msg_id], min(rates[msg_id] * factor, config.max_telemetry_hz))
    return rates


_STATE_MESSAGES = (mavlink.MAVLINK_MSG_ID_HEARTBEAT, mavlink.MAVLINK_MSG_ID_EXTENDED_SYS_STATE)
"""Faster than real time, a change of arming, mode, status or landed state is sent at once: a client
timing its waits on the vehicle's clock (×k) would otherwise wait up to k simulated seconds for the
1 Hz HEARTBEAT (PX4's rate, in wall time) that shows the mode it asked for."""


def _state_key(snap: VehicleSnapshot) -> tuple[object, ...]:
    return (snap.armed, snap.mode, snap.system_status, snap.landed_state)


def _statustext(severity: int, text: str, text_id: int) -> list[mavlink.MAVLink_message]:
    """STATUSTEXT messages for `text`: one, or MAVLink 2 chunks (`text_id`, chunk_seq) beyond 50 bytes."""
    data = text.encode("utf-8", errors="replace")
    if len(data) <= _STATUSTEXT_CHUNK:
        return [mavlink.MAVLink_statustext_message(severity, data)]
    chunks = [data[i : i + _STATUSTEXT_CHUNK] for i in range(0, len(data), _STATUSTEXT_CHUNK)]
    return [mavlink.MAVLink_statustext_message(severity, c, text_id, i) for i, c in enumerate(chunks)]
