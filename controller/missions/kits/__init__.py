"""The kits of a mission: everything one flight needs, built for each way to fly (see `base.FlightKit`).

`open_kit(mission, out_dir)` imports the kit for `mission.vehicle` lazily, so a real-vehicle mission
loads no simulator."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

from controller.missions.kits.base import FlightKit, LoadedModels
from controller.missions.schema import ARDUPILOT_SITL, PX4_SITL, SIM, SIM_MAVLINK, Mission
from drone_inspect_core.signing import SigningKey
from flight.safety import SafetyLimits


@contextmanager
def open_kit(
    mission: Mission,
    out_dir: Path,
    limits: SafetyLimits | None = None,
    models: LoadedModels | None = None,
    signing_key: SigningKey | None = None,
) -> Iterator[FlightKit]:
    """The mission's components, closed (vehicle, camera, sim subprocess) when the block ends.

    `signing_key`: a real vehicle's MAVLink signing key; a vehicle the run starts gets its own (the
    sim-vehicle), or has none (PX4 v1.15), so a key given for one is refused."""
    if signing_key is not None and not mission.is_real:
        raise ValueError(
            f"a signing key is for a real vehicle set up with it; {mission.vehicle} gets a key of its own "
            "per run (sim-mavlink) or cannot sign (px4-sitl: PX4 v1.15 has no signing)"
        )
    with ExitStack() as stack:
        if mission.vehicle == SIM:
            from controller.missions.kits.sim import open_sim_kit

            yield stack.enter_context(open_sim_kit(mission, limits, models))
        elif mission.vehicle == SIM_MAVLINK:
            from controller.missions.kits.sim_mavlink import open_sim_mavlink_kit

            yield stack.enter_context(open_sim_mavlink_kit(mission, out_dir, models, limits))
        elif mission.vehicle == PX4_SITL:
            from controller.missions.kits.px4_sitl import open_px4_sitl_kit

            yield stack.enter_context(open_px4_sitl_kit(mission, out_dir, models, limits))
        elif mission.vehicle == ARDUPILOT_SITL:
            from controller.missions.kits.ardupilot_sitl import open_ardupilot_sitl_kit

            yield stack.enter_context(open_ardupilot_sitl_kit(mission, out_dir, models))
        else:
            from controller.missions.kits.real import open_real_kit

            yield stack.enter_context(open_real_kit(mission, out_dir, models, signing_key))
