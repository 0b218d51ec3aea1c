"""The kit of a real vehicle: its MAVLink URL and the stream camera on its camera URL; no truth.

The backend follows the vehicle's autopilot (`mission.autopilot`; "auto": its HEARTBEAT says):
MAVSDK for PX4, the GUIDED-mode backend for ArduPilot (`flight.autopilots.MavlinkVehicle`).

For a `udpin://` URL the .tlog relay takes the URL's port and MAVSDK listens behind it
(`REAL_CLIENT_PORT_SHIFT` higher); other links are flown without a .tlog. Nothing here
imports the simulator: a real-vehicle mission loads no `sim_world` module and no PyBullet.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

from controller.missions.kits.base import (
    TLOG_NAME,
    FlightKit,
    LoadedModels,
    image_detector_for,
    planner_for,
)
from controller.missions.schema import Mission
from flight.autopilots import MavlinkVehicle
from flight.relay import MavlinkRelay
from flight.urls import udpin_address
from perception.stream_camera import StreamCamera

log = logging.getLogger(__name__)

REAL_CLIENT_PORT_SHIFT = 1000


@contextmanager
def open_real_kit(mission: Mission, out_dir: Path, models: LoadedModels | None = None) -> Iterator[FlightKit]:
    """A vehicle at `mission.vehicle` and its camera stream; no truth. Fails fast on a bad URL."""
    with ExitStack() as stack:
        url = mission.vehicle
        tlog = None
        address = udpin_address(url)
        if address is not None:
            # The relay takes the vehicle's port on the host the URL names, and locks onto the first
            # autopilot heard there; MAVSDK listens behind it on loopback, REAL_CLIENT_PORT_SHIFT higher.
            host, port = address
            relay = MavlinkRelay(
                port,
                port + REAL_CLIENT_PORT_SHIFT,
                out_dir / TLOG_NAME,
                listen_host=host,
                faults=mission.faults.link_faults(),
            )
            tlog = stack.enter_context(relay)
            url = f"udpin://127.0.0.1:{port + REAL_CLIENT_PORT_SHIFT}"
        else:
            log.warning("%s is not a udpin:// link: flying without a .tlog", url)
        vehicle = stack.enter_context(MavlinkVehicle(url, mission.autopilot, shown_url=mission.vehicle))
        camera = stack.enter_context(StreamCamera(mission.camera, timeout_s=3.0, open_timeout_s=10.0))
        planner = planner_for(mission, models, None)
        frame = camera.read()
        yield FlightKit(
            vehicle=vehicle,
            camera=camera,
            detector=image_detector_for(mission, models),
            planner=planner,
            instruction=mission.instruction_text(mission.target_kind, mission.target_attribute),
            info={
                "backend": "MAVLink (MAVSDK for PX4, GUIDED for ArduPilot) + stream camera",
                "autopilot": mission.autopilot,
                "vehicle": mission.vehicle,
                "camera": mission.camera,
            },
            tlog=tlog,
            image_width_px=frame.width,
        )
