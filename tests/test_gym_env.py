"""`DroneInspect/Centring-v0`: Gymnasium's own checker, reset options, rewards, termination,
truncation, bad input, and policies run in it (the latent planner beats a random one)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import controller.evaluation.gym_env as gym_env
from controller.evaluation.gym_policies import evaluate, wilson_interval
from controller.planning.actions import Action, XMove, ZMove, label_from_offset

LEFT = Action(XMove.LEFT, ZMove.NONE).index
RIGHT = Action(XMove.RIGHT, ZMove.NONE).index
NONE = Action(XMove.NONE, ZMove.NONE).index
START_RIGHT = {"right_m": 0.5, "up_m": 0.0, "distance_m": 2.0, "yaw_deg": 0.0}


@pytest.fixture
def env():
    environment = gym.make(gym_env.ENV_ID, render_mode="rgb_array")
    yield environment.unwrapped
    environment.close()


def test_registered_on_import_and_passes_gymnasiums_env_checker(env) -> None:
    assert gym_env.ENV_ID in gym.registry
    check_env(env, skip_render_check=False)
    assert env.action_space.n == 9
    assert env.observation_space["image"].shape == (224, 224, 3)


def test_reset_is_reproducible_and_its_options_choose_scene_kind_start_and_words(env) -> None:
    obs_a, info_a = env.reset(seed=5)
    obs_b, info_b = env.reset(seed=5)
    assert np.array_equal(obs_a["image"], obs_b["image"])
    assert info_a["scene_seed"] == info_b["scene_seed"] and info_a["start"] == info_b["start"]
    assert (
        obs_a["instruction"]
        == f"Center the {info_a['target_kind'].replace('switchbox', 'switch box')} in the camera view."
    )
    obs_c, _ = env.reset(seed=6)
    assert not np.array_equal(obs_a["image"], obs_c["image"])

    obs, info = env.reset(
        seed=1,
        options={
            "scene_seed": 4242,
            "target_kind": "valve",
            "start": START_RIGHT,
            "instruction": "the valve, please",
        },
    )
    assert info["target_kind"] == "valve" and info["scene_seed"] == 4242
    assert obs["instruction"] == "the valve, please"
    du, dv = info["offset_px"]
    assert du < -env.epsilon_px and abs(dv) < env.epsilon_px  # drone right of the target: target on the left


def test_reward_is_progress_towards_the_centre(env) -> None:
    env.reset(seed=1, options={"scene_seed": 4242, "start": START_RIGHT})
    before = abs(env._info_offset[0])
    _, reward_towards, terminated, truncated, info = env.step(LEFT)
    assert abs(info["offset_px"][0]) < before - 10 and reward_towards > 0
    assert not terminated and not truncated and info["steps"] == 1
    env.reset(seed=1, options={"scene_seed": 4242, "start": START_RIGHT})
    _, reward_away, _, _, info = env.step(RIGHT)
    assert abs(info["offset_px"][0]) > before + 10 and reward_away < 0


def test_terminates_when_centred_and_truncates_at_the_step_budget(env) -> None:
    _, info = env.reset(seed=2, options={"scene_seed": 77, "start": {**START_RIGHT, "up_m": -0.3}})
    terminated = truncated = False
    while not (terminated or truncated):
        du, dv = info["offset_px"]
        _, reward, terminated, truncated, info = env.step(label_from_offset(du, dv, env.epsilon_px).index)
    assert terminated and not truncated and info["outcome"] == "centred" and info["centred"]
    assert reward > gym_env.CENTRED_BONUS - gym_env.STEP_COST - 0.5
    with pytest.raises(RuntimeError, match="reset"):
        env.step(NONE)
    frame = env.render()
    assert frame.shape == (224, 224, 3) and tuple(frame[112 - 10, 112]) == (255, 255, 0)  # the ε box

    short = gym_env.CentringEnv(max_steps=2)
    try:
        short.reset(seed=3, options={"start": START_RIGHT})
        assert short.step(NONE)[2:4] == (False, False)
        _, _, terminated, truncated, info = short.step(NONE)
        assert (terminated, truncated, info["outcome"]) == (False, True, "max_steps")
    finally:
        short.close()


def test_bad_input_is_refused_with_a_clear_error(env) -> None:
    with pytest.raises(ValueError, match="unknown reset options"):
        env.reset(seed=0, options={"scene": 1})
    with pytest.raises(ValueError, match="target_kind"):
        env.reset(seed=0, options={"target_kind": "ladder"})
    with pytest.raises(ValueError, match="charset"):
        env.reset(seed=0, options={"instruction": "centre the gauge ✓"})
    with pytest.raises(ValueError, match="start"):
        env.reset(seed=0, options={"start": {"right_m": 99}})
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(9)
    with pytest.raises(ValueError, match="moves"):
        gym_env.CentringEnv(moves="teleport")
    with pytest.raises(ValueError, match="instructions"):
        gym_env.CentringEnv(instructions="poetry")


def test_the_latent_planner_as_a_policy_beats_a_random_one_on_the_same_episodes() -> None:
    result = evaluate(["latent", "random"], episodes=6, seed=11)
    latent, random = result["latent"]["summary"], result["random"]["summary"]
    assert latent["centred"] >= 5 and latent["centred"] > random["centred"]
    seen = [(e["scene_seed"], e["instruction"]) for e in result["latent"]["episodes"]]
    assert seen == [(e["scene_seed"], e["instruction"]) for e in result["random"]["episodes"]]
    assert len({s for s, _ in seen}) == 6


def test_wilson_interval() -> None:
    low, high = wilson_interval(97, 100)
    assert round(low, 3) == 0.915 and round(high, 3) == 0.99  # the textbook values for 97/100
    assert wilson_interval(0, 10)[0] == 0.0 and wilson_interval(10, 10)[1] == 1.0
