"""What the centring loop is given for a mission: ε, the words it understands, one instruction's settings.

Shared by every flight of a mission (`controller.missions.session`) and resolved once per flight
(ε) or per instruction (the loop's configuration).
"""

from __future__ import annotations

from controller.missions.kits.base import FlightKit
from controller.missions.schema import Mission
from controller.missions.vehicles import simulator_speed_of
from controller.planning.grounding import TargetQuery, understand
from controller.planning.loop_records import CentringConfig
from drone_inspect_core.centring import default_epsilon_px
from drone_inspect_core.sim_speed import OFF_REAL_TIME_FRESH_FRAME_S, SimSpeed, off_real_time
from drone_inspect_core.vocabulary import Vocabulary, parse_kinds


def epsilon_for(mission: Mission, kit: FlightKit) -> float:
    """ε for this flight: the kit's (tests fix it), else the mission's, else the default for the width."""
    return kit.epsilon_px or mission.epsilon_px or default_epsilon_px(kit.image_width_px)


def mission_vocabulary(mission: Mission) -> Vocabulary:
    """The words of a mission: the shipped ones, the kinds of its scene (a file's too, for a simulated
    vehicle), of the mission itself and of its detector and planner checkpoints, and its glossary."""
    if mission.is_real:
        return mission.vocabulary
    from controller.missions.setup import scene_config_for  # the simulator's scene code: simulated only

    vocabulary = scene_config_for(mission).vocabulary.with_kinds(parse_kinds(mission.model_kinds()))
    return vocabulary.with_glossary(mission.glossary_words())


def loop_config(
    mission: Mission,
    epsilon_px: float,
    instruction: str,
    target: TargetQuery | None = None,
    vocabulary: Vocabulary | None = None,
) -> CentringConfig:
    """The loop's configuration for one instruction of `mission`. The instruction is understood here,
    before anything flies: one the vocabulary cannot act on raises `InstructionRefused` naming its word."""
    vocabulary = vocabulary or mission_vocabulary(mission)
    return CentringConfig(
        **mission.loop.model_dump(),
        epsilon_px=epsilon_px,
        instruction=instruction,
        target=target or understand(instruction, vocabulary),
        vocabulary=vocabulary,
        max_steps=mission.max_steps,
        timeout_s=mission.timeout_s,
        stop_margin_px=mission.stop_margin_px,
        **({"fresh_frame_s": OFF_REAL_TIME_FRESH_FRAME_S} if off_real_time(simulator_speed(mission)) else {}),
    )


def simulator_speed(mission: Mission) -> SimSpeed | None:
    """The speed of the mission's simulator behind a MAVLink link (sim-mavlink's `sim_speed`, a SITL's
    `speed`); None for the in-process simulation and a real vehicle. Off real time
    (`drone_inspect_core.sim_speed.off_real_time`), its camera's frames lag the vehicle by more than at ×1,
    on the vehicle's clock."""
    return simulator_speed_of(mission.vehicle, mission.sim_speed, mission.px4.speed, mission.ardupilot.speed)
