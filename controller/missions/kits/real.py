"""The kit of a real vehicle: MAVSDK on the mission's URL and the stream camera on its camera URL; no truth.

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
    image_detector_for,
    link_faults_for,
    planner_for,
)
from controller.missions.schema import Mission
from drone_inspect_core.signing import SigningKey
from flight.mavsdk_backend import MavsdkConfig, MavsdkVehicle
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
    with ExitStack() as stack:
        faults = link_faults_for(mission)
        relay, url = relay_in_front(mission.vehicle, out_dir / TLOG_NAME, faults, signing_key)
        tlog = None if relay is None else stack.enter_context(relay)
        if relay is None:
            log.warning("%s is not a udpin:// link: flying without a .tlog", url)
        vehicle = stack.enter_context(MavsdkVehicle(MavsdkConfig(url=url, shown_url=mission.vehicle)))
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
                "backend": "MAVSDK + stream camera",
                "vehicle": mission.vehicle,
                "camera": mission.camera,
                "mavlink_signing": "the vehicle's key (--signing-key)" if signing_key else "off",
            },
            tlog=tlog,
            image_width_px=frame.width,
        )
