"""Policies in `DroneInspect/Centring-v0` and their success rates (`dronectl gym-eval`).

- `latent`: the shipped latent planner (or a checkpoint) picks the action from the observation
  alone (camera image and instruction), as it does in a mission.
- `random`: a uniformly random action, seeded.
- `oracle`: the correct action from simulator truth (`info["offset_px"]`): a ceiling, not a policy
  a real drone could run.

Episode i of a run is `reset(seed=episode_seed(seed, i))`, so every policy meets the same scenes,
starts and phrasings.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from controller.evaluation.gym_env import CentringEnv
from controller.planning.actions import NUM_ACTIONS, label_from_offset
from controller.planning.planners import LatentPlannerAdapter, Observation
from drone_inspect_core.stats import wilson_interval

POLICIES = ("latent", "random", "oracle")
Policy = Callable[[dict[str, Any], dict[str, Any]], int]
"""(observation, info) → action index."""


def episode_seed(seed: int, index: int) -> int:
    return int(np.random.SeedSequence([seed, index, 0x6E7]).generate_state(1)[0] >> 1)


def make_policy(name: str, epsilon_px: float, seed: int = 0, checkpoint: str | Path | None = None) -> Policy:
    if name == "latent":
        planner = LatentPlannerAdapter(checkpoint)

        def latent(obs: dict[str, Any], info: dict[str, Any]) -> int:
            seen = Observation(obs["image"], None, obs["instruction"], epsilon_px)
            return planner.plan(seen).action.index

        return latent
    if name == "random":
        rng = np.random.default_rng(seed)
        return lambda obs, info: int(rng.integers(NUM_ACTIONS))
    if name == "oracle":

        def oracle(obs: dict[str, Any], info: dict[str, Any]) -> int:
            offset = info["offset_px"]
            return 4 if offset is None else label_from_offset(offset[0], offset[1], epsilon_px).index

        return oracle
    raise ValueError(f"unknown policy {name!r}: choose from {', '.join(POLICIES)}")


@dataclass(frozen=True)
class Episode:
    policy: str
    index: int
    seed: int
    scene_seed: int
    target_kind: str
    instruction: str
    outcome: str
    steps: int
    episode_return: float
    final_offset_px: tuple[float, float] | None


def run_policy(env: CentringEnv, name: str, policy: Policy, episodes: int, seed: int) -> list[Episode]:
    rows = []
    for index in range(episodes):
        ep_seed = episode_seed(seed, index)
        obs, info = env.reset(seed=ep_seed)
        total, done = 0.0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(policy(obs, info))
            total += reward
            done = terminated or truncated
        rows.append(
            Episode(
                name, index, ep_seed, info["scene_seed"], info["target_kind"], info["instruction"],
                info["outcome"], info["steps"], round(total, 4), info["offset_px"],
            )
        )  # fmt: skip
    return rows


def summarise(rows: list[Episode], wall_s: float) -> dict[str, Any]:
    n = len(rows)
    centred = [r for r in rows if r.outcome == "centred"]
    low, high = wilson_interval(len(centred), n)
    outcomes: dict[str, int] = {}
    for r in rows:
        outcomes[r.outcome] = outcomes.get(r.outcome, 0) + 1
    return {
        "episodes": n,
        "centred": len(centred),
        "success": len(centred) / n if n else 0.0,
        "success_ci95": (round(low, 4), round(high, 4)),
        "mean_steps_centred": (sum(r.steps for r in centred) / len(centred)) if centred else None,
        "mean_return": sum(r.episode_return for r in rows) / n if n else 0.0,
        "outcomes": outcomes,
        "wall_s": round(wall_s, 1),
    }


def evaluate(
    policies: list[str],
    episodes: int,
    seed: int,
    env_kwargs: dict[str, Any] | None = None,
    checkpoint: str | Path | None = None,
) -> dict[str, Any]:
    """Every policy over the same `episodes` episodes; a summary per policy and every episode's row."""
    unknown = [p for p in policies if p not in POLICIES]
    if unknown or not policies:
        raise ValueError(f"policies must be among {', '.join(POLICIES)}; got {policies}")
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    env = CentringEnv(**(env_kwargs or {}))
    out: dict[str, Any] = {"env": {"id": "DroneInspect/Centring-v0", **(env_kwargs or {})}, "seed": seed}
    try:
        for name in policies:
            t0 = time.perf_counter()
            rows = run_policy(env, name, make_policy(name, env.epsilon_px, seed, checkpoint), episodes, seed)
            out[name] = {
                "summary": summarise(rows, time.perf_counter() - t0),
                "episodes": [asdict(r) for r in rows],
            }
    finally:
        env.close()
    return out


def format_table(result: dict[str, Any], policies: list[str]) -> str:
    lines = [f"{'policy':<8} {'centred':>9} {'success':>8} {'95 % CI':>15} {'mean steps':>10} {'return':>7}"]
    for name in policies:
        s = result[name]["summary"]
        low, high = s["success_ci95"]
        steps = "-" if s["mean_steps_centred"] is None else f"{s['mean_steps_centred']:.2f}"
        lines.append(
            f"{name:<8} {s['centred']:>4}/{s['episodes']:<4} {100 * s['success']:>7.1f}% "
            f"{100 * low:>6.1f}–{100 * high:>5.1f} % {steps:>10} {s['mean_return']:>7.2f}"
        )
    return "\n".join(lines)
