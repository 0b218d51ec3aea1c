"""The kit of a real vehicle: MAVSDK on the mission's URL and the stream camera on its camera URL; no truth.

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
    OpenedVehicle,
    image_detector_for,
    link_faults_for,
    planner_for,
)
from controller.missions.schema import Mission
from flight.link_faults import LinkFaults
from flight.mavsdk_backend import MavsdkConfig, MavsdkVehicle
from flight.relay import MavlinkRelay
from flight.urls import udpin_address
from perception.stream_camera import StreamCamera

log = logging.getLogger(__name__)

REAL_CLIENT_PORT_SHIFT = 1000


@contextmanager
def open_real_kit(mission: Mission, out_dir: Path, models: LoadedModels | None = None) -> Iterator[FlightKit]:
    """A vehicle at `mission.vehicle` and its camera stream; no truth. Fails fast on a bad URL."""
    with open_real_vehicle(mission.vehicle, mission.camera, out_dir, link_faults_for(mission)) as opened:
        frame = opened.camera.read()
        yield FlightKit(
            vehicle=opened.vehicle,
            camera=opened.camera,
            detector=image_detector_for(mission, models),
            planner=planner_for(mission, models, None),
            instruction=mission.instruction_text(mission.target_kind, mission.target_attribute),
            info=opened.info,
            tlog=opened.tlog,
            image_width_px=frame.width,
        )


@contextmanager
def open_real_vehicle(
    vehicle_url: str, camera_url: str, out_dir: Path, faults: LinkFaults | None = None
) -> Iterator[OpenedVehicle]:
    """MAVSDK on `vehicle_url` (behind the .tlog relay for a udpin:// link) and the camera stream."""
    with ExitStack() as stack:
        url = vehicle_url
        tlog = None
        address = udpin_address(url)
        if address is not None:
            # The relay takes the vehicle's port on the host the URL names, and locks onto the first
            # autopilot heard there; MAVSDK listens behind it on loopback, REAL_CLIENT_PORT_SHIFT higher.
            host, port = address
            relay = MavlinkRelay(
                port, port + REAL_CLIENT_PORT_SHIFT, out_dir / TLOG_NAME, listen_host=host, faults=faults
            )
            tlog = stack.enter_context(relay)
            url = f"udpin://127.0.0.1:{port + REAL_CLIENT_PORT_SHIFT}"
        else:
            log.warning("%s is not a udpin:// link: flying without a .tlog", url)
        vehicle = stack.enter_context(MavsdkVehicle(MavsdkConfig(url=url, shown_url=vehicle_url)))
        camera = stack.enter_context(StreamCamera(camera_url, timeout_s=3.0, open_timeout_s=10.0))
        info = {"backend": "MAVSDK + stream camera", "vehicle": vehicle_url, "camera": camera_url}
        yield OpenedVehicle(vehicle, camera, info, tlog)
