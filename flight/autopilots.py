"""Which backend flies the vehicle at a MAVLink URL: PX4 with MAVSDK, ArduPilot in GUIDED mode.

`detect_autopilot(url)` listens on the URL for the first autopilot HEARTBEAT (component 1, not a ground
station) and reads its `autopilot` field: 3 (MAV_AUTOPILOT_ARDUPILOTMEGA) is ArduPilot, anything else
(PX4 is 12; the project's sim-vehicle says PX4 too) is flown as PX4. The link is closed again before
the backend opens it. `MavlinkVehicle(url, autopilot)` is the `Vehicle` at a URL: on `connect()` it
detects the autopilot ("auto"; "px4" / "ardupilot" skip the wait), builds that backend and hands every
call to it, so a real ArduPilot vehicle is one URL away as a PX4 one is, and a vehicle that never
answers fails in `connect()` like any other.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

from flight.errors import CommandDeniedError, VehicleConnectionError
from flight.pymavlink_link import MavlinkLink
from flight.safety import FlightTimeouts
from flight.types import Closable, Telemetry, VelocityBody
from flight.vehicle import Vehicle

log = logging.getLogger(__name__)

AUTOPILOTS = ("px4", "ardupilot")


def detect_autopilot(url: str, timeout_s: float, shown_url: str | None = None) -> str:
    """The autopilot ("px4" or "ardupilot") of the first autopilot heartbeat on `url` (else an error)."""
    found: list[int] = []
    heard = threading.Event()

    def on_message(msg: Any) -> None:
        if (
            msg.get_type() == "HEARTBEAT"
            and msg.get_srcComponent() == mavlink.MAV_COMP_ID_AUTOPILOT1
            and msg.type != mavlink.MAV_TYPE_GCS
            and msg.autopilot != mavlink.MAV_AUTOPILOT_INVALID
        ):
            found.append(msg.autopilot)
            heard.set()

    started = time.monotonic()
    with MavlinkLink(url, on_message):
        if not heard.wait(timeout_s):
            where = url if shown_url in (None, url) else f"{shown_url} (relayed to {url})"
            raise VehicleConnectionError(
                "connect()", "NO_AUTOPILOT",
                f"no autopilot heartbeat on {where} within {timeout_s:.1f} s: is the vehicle running and "
                "sending to this address and port?",
            )  # fmt: skip
    autopilot = "ardupilot" if found[0] == mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA else "px4"
    log.info("%s: %s (MAV_AUTOPILOT %d), heard after %.1f s", shown_url or url, autopilot, found[0],
             time.monotonic() - started)  # fmt: skip
    return autopilot


class MavlinkVehicle(Vehicle):
    """The vehicle at a MAVLink URL, flown by the backend its autopilot needs (chosen on `connect()`)."""

    def __init__(
        self, url: str, autopilot: str = "auto", shown_url: str | None = None, link: Closable | None = None
    ) -> None:
        """`link`: what carries the connection and goes with it (a relay in front), closed last."""
        if autopilot not in ("auto", *AUTOPILOTS):
            raise ValueError(f"autopilot must be auto, px4 or ardupilot, got {autopilot!r}")
        self.url, self.autopilot, self.shown_url = url, autopilot, shown_url
        self.inner: Vehicle | None = None
        self._link = link

    def connect(self, timeout_s: float | None = None) -> None:
        if self.inner is None:
            timeout_s = timeout_s or FlightTimeouts().connect_s
            started = time.monotonic()
            if self.autopilot == "auto":
                self.autopilot = detect_autopilot(self.url, timeout_s, self.shown_url)
            self.inner = self._backend()
            timeout_s = max(1.0, timeout_s - (time.monotonic() - started))
        self.inner.connect(timeout_s)

    def _backend(self) -> Vehicle:
        if self.autopilot == "ardupilot":
            from flight.ardupilot.vehicle import ArduPilotConfig, ArduPilotVehicle

            return ArduPilotVehicle(ArduPilotConfig(url=self.url, shown_url=self.shown_url))
        from flight.mavsdk.vehicle import MavsdkConfig, MavsdkVehicle

        return MavsdkVehicle(MavsdkConfig(url=self.url, shown_url=self.shown_url))

    def _require(self, origin: str) -> Vehicle:
        if self.inner is None:
            raise CommandDeniedError(origin, "NOT_CONNECTED", "call connect() first")
        return self.inner

    @property
    def realtime(self) -> bool:  # type: ignore[override]
        return True if self.inner is None else self.inner.realtime

    @property
    def wall_paced_telemetry(self) -> bool:  # type: ignore[override]
        return False if self.inner is None else self.inner.wall_paced_telemetry

    def wait_ready(self, timeout_s: float | None = None) -> None:
        self._require("wait_ready()").wait_ready(timeout_s)

    def prepare_takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        self._require("prepare_takeoff()").prepare_takeoff(altitude_m, timeout_s)

    def arm(self, timeout_s: float | None = None) -> None:
        self._require("arm()").arm(timeout_s)

    def takeoff(self, altitude_m: float, timeout_s: float | None = None) -> None:
        self._require("takeoff()").takeoff(altitude_m, timeout_s)

    def start_offboard(self, timeout_s: float | None = None) -> None:
        self._require("start_offboard()").start_offboard(timeout_s)

    def set_velocity_body(self, velocity: VelocityBody) -> None:
        self._require("set_velocity_body()").set_velocity_body(velocity)

    def hold(self) -> None:
        self._require("hold()").hold()

    def stop_offboard(self, timeout_s: float | None = None) -> None:
        self._require("stop_offboard()").stop_offboard(timeout_s)

    def land(self, timeout_s: float | None = None) -> None:
        self._require("land()").land(timeout_s)

    def disarm(self, timeout_s: float | None = None) -> None:
        self._require("disarm()").disarm(timeout_s)

    def telemetry(self) -> Telemetry:
        return self._require("telemetry()").telemetry()

    def time_s(self) -> float:
        return time.monotonic() if self.inner is None else self.inner.time_s()

    def sleep(self, seconds: float) -> None:
        if self.inner is None:
            time.sleep(max(0.0, seconds))
        else:
            self.inner.sleep(seconds)

    def status_texts(self) -> list[str]:
        return [] if self.inner is None else self.inner.status_texts()

    def close(self) -> None:
        try:
            if self.inner is not None:
                self.inner.close()
        finally:
            link, self._link = self._link, None
            if link is not None:
                link.close()
