"""What a mission's simulated world is: its scene family, start, wind and link faults.

Shared by the kits of the simulated vehicles; a real-vehicle mission never imports it
(it would load the simulator's scene code).
"""

from __future__ import annotations

from dataclasses import replace

from controller.missions.schema import Mission, RandomStartSpec, StartOffset
from sim_world.physics.wind import WindConfig
from sim_world.scene.config import (
    DEFAULT_SCENE,
    SceneConfig,
    load_scene_config,
    parse_scene_config,
    with_targets,
)


def scene_config_for(mission: Mission) -> SceneConfig:
    """The mission's scene family (file, inline or default), restricted to its target kind, with the
    mission's `targets` (exactly that many), `twins` and the named target's `target_attribute`.

    A mission with one target, no twins and no attribute keeps the scene file's own `target.count` and
    `twins` (a `scenes/multi.yaml` mission still draws 2-4 targets)."""
    spec = mission.scene.config
    if spec is None:
        config = DEFAULT_SCENE
    elif isinstance(spec, str):
        config = load_scene_config(spec)
    else:
        config = parse_scene_config(spec, source=f"mission {mission.name}: scene.config")
    if mission.kinds or mission.target_kind is not None:  # validated again: the kind must be the scene's
        data = config.model_dump(mode="json")
        data["kinds"] = {**data["kinds"], **mission.kinds}
        if mission.target_kind is not None:
            data["target"]["kinds"] = [mission.target_kind]
        config = parse_scene_config(data, source=f"mission {mission.name}: kinds/target_kind over its scene")
    if mission.targets != 1 or mission.twins or mission.target_attribute is not None:
        config = with_targets(
            config,
            count=(mission.targets, mission.targets) if mission.targets != 1 else None,
            twins=mission.twins or None,
            attribute=mission.target_attribute,
            source=f"mission {mission.name}: targets/twins/target_attribute over its scene",
        )
    return config


def wind_config_for(mission: Mission) -> WindConfig:
    """The mission's wind for a simulated world (calm when it names none); `faults.gust_m_s`: the gusts."""
    wind = WindConfig()
    if mission.wind is not None:
        wind = WindConfig(
            mean_enu_m_s=mission.wind.mean_enu_m_s,
            gust_std_m_s=mission.wind.gust_std_m_s,
            gust_time_constant_s=mission.wind.gust_time_constant_s,
        )
    if mission.faults.gust_m_s:
        wind = replace(wind, gust_std_m_s=mission.faults.gust_m_s)
    return wind


def start_offset_for(mission: Mission, hfov_deg: float, vfov_deg: float) -> StartOffset:
    """The fixed start, or the seeded random draw for this camera."""
    if isinstance(mission.start, RandomStartSpec):
        return mission.start.random.draw(hfov_deg, vfov_deg)
    return mission.start
