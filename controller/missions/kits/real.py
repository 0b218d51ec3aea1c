"""The kit of a real vehicle: its MAVLink URL and the stream camera on its camera URL; no truth.

The backend follows the vehicle's autopilot (`mission.autopilot`; "auto": its HEARTBEAT says):
MAVSDK for PX4, the GUIDED-mode backend for ArduPilot (`flight.autopilots.MavlinkVehicle`).

For a `udpin://` URL the .tlog relay takes the URL's host and port and MAVSDK listens behind it on a
free loopback port (`flight.relay.relay_in_front`); with a signing key (`--signing-key FILE`, a vehicle
set up with that key) the relay signs for MAVSDK and passes on only what the vehicle signed. Other
links are flown without a .tlog, and cannot be signed. Nothing here imports the simulator: a
real-vehicle mission loads no `sim_world` module and no PyBullet.
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
    planner_for,
)
from controller.missions.schema import Mission
from drone_inspect_core.signing import SigningKey
from flight.autopilots import MavlinkVehicle
from flight.link_faults import LinkFaults
from flight.relay import relay_in_front
from perception.stream_camera import StreamCamera

log = logging.getLogger(__name__)


@contextmanager
def open_real_kit(
    mission: Mission,
    out_dir: Path,
    models: LoadedModels | None = None,
    signing_key: SigningKey | None = None,
) -> Iterator[FlightKit]:
    """A vehicle at `mission.vehicle` and its camera stream; no truth. Fails fast on a bad URL."""
    faults = mission.faults.link_faults()
    with open_real_vehicle(
        mission.vehicle, mission.camera, out_dir, mission.autopilot, faults, signing_key
    ) as opened:
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
    vehicle_url: str,
    camera_url: str,
    out_dir: Path,
    autopilot: str = "auto",
    faults: LinkFaults | None = None,
    signing_key: SigningKey | None = None,
) -> Iterator[OpenedVehicle]:
    """The vehicle at `vehicle_url` (behind the .tlog relay for a udpin:// link, which signs with
    `signing_key`; its autopilot's backend, `flight.autopilots.MavlinkVehicle`) and the camera stream."""
    with ExitStack() as stack:
        relay, url = relay_in_front(vehicle_url, out_dir / TLOG_NAME, faults, signing_key)
        tlog = None if relay is None else stack.enter_context(relay)
        if relay is None:
            log.warning("%s is not a udpin:// link: flying without a .tlog", url)
        vehicle = stack.enter_context(MavlinkVehicle(url, autopilot, shown_url=vehicle_url))
        camera = stack.enter_context(StreamCamera(camera_url, timeout_s=3.0, open_timeout_s=10.0))
        info = {
            "backend": "MAVLink (MAVSDK for PX4, GUIDED for ArduPilot) + stream camera",
            "autopilot": autopilot,
            "vehicle": vehicle_url,
            "camera": camera_url,
            "mavlink_signing": "the vehicle's key (--signing-key)" if signing_key else "off",
        }
        yield OpenedVehicle(vehicle, camera, info, tlog)
