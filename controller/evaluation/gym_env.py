"""The centring task as a Gymnasium environment: `DroneInspect/Centring-v0`, registered on import.

    import gymnasium as gym
    import controller.evaluation.gym_env  # registers DroneInspect/Centring-v0
    env = gym.make("DroneInspect/Centring-v0", render_mode="rgb_array")
    obs, info = env.reset(seed=0, options={"target_kind": "valve"})

An episode is one centring mission in the in-process PyBullet world, flown exactly as
`dronectl fly` flies it (the same world, autopilot, camera and move execution): the
drone takes off, is placed at a start pose with the target off-centre, and every step
flies one of the paper's 9 discrete moves (`controller.planning.actions`: index =
3 · x + z, x ∈ {left, none, right}, z ∈ {up, none, down}), then hovers until settled.

- **Observation**: `{"image": (224, 224, 3) uint8 RGB, "instruction": str}`; the instruction
  names the scene's target ("Center the valve in the camera view.").
- **Moves** (`moves`): "fixed", the paper's lengths: 0.3 m per axis, halved when that axis
  reverses, down to 0.05 m (the loop's fixed schedule); "constant": always `move_m`.
  Action 4 ("none") hovers for 0.3 s.
- **Reward**: progress towards the centre, `(e_prev − e) / (W/2)` with e = max(|du|, |dv|)
  the target's pixel offset per simulator truth, minus 0.01 per step; +1 when centred,
  −1 when the target leaves the view.
- **Termination**: the target within ε (default 10 px at 224 px) of the image centre on both
  axes per truth (`terminated`, info "outcome" = "centred"), or out of view ("target_lost").
  **Truncation**: `max_steps` moves without either (info "outcome" = "max_steps").
- **Constructor**: `scene` (a scene file or mapping; default the shipped family) and `kinds` (kinds
  of your own, as a mission's `kinds:`) choose the world; `target_kind` may then name one of them.
- **`reset(seed=…, options=…)`**: options `scene_seed` (int), `target_kind` ("gauge", "valve",
  "switchbox" or a kind of the scene's), `start` (`{right_m, up_m, distance_m, yaw_deg}`, the drone's
  offset from the centred pose), `instruction` (str). Unset ones are drawn from the episode's seed: an unseen
  scene, a start with the target 15–80 % of the half view off-centre, a phrasing from the
  `instructions` corpus ("fixed", "train" or "heldout").
- **`info`**: `offset_px` (truth, None out of view), `centred`, `outcome`, `scene_seed`,
  `target_kind`, `start`, `epsilon_px`, `steps`, `sim_time_s`.

Truth is used for the reward and termination only; the observation holds what a real drone
has: its camera and the operator's words.
"""

from __future__ import annotations

import copy
import string
from contextlib import ExitStack
from typing import Any, ClassVar

import numpy as np

try:
    import gymnasium as gym
    from gymnasium import spaces
except ImportError as exc:  # pragma: no cover - depends on the installed extras
    raise ImportError(
        "controller.evaluation.gym_env needs Gymnasium: pip install -e '.[gym]' (or pip install gymnasium)"
    ) from exc

from controller.missions.kits.sim import SimWorld, open_sim_world
from controller.missions.schema import Mission, parse_mission
from controller.planning.actions import ALL_ACTIONS, Action
from controller.planning.loop_records import LoopSettings, MoveSchedule
from controller.training.instructions import CORPORA, builtin_templates, fill
from drone_inspect_core.centring import default_epsilon_px, within
from flight.moves import fly_offset, take_off_to_start

ENV_ID = "DroneInspect/Centring-v0"
MOVES = ("fixed", "constant")
INSTRUCTION_CHARSET = frozenset(string.ascii_letters + string.digits + " .,;:!?'\"-()/&")
MAX_INSTRUCTION_CHARS = 200
STEP_COST = 0.01
CENTRED_BONUS = 1.0
LOST_PENALTY = 1.0
_LOOP = LoopSettings()  # the loop's own defaults: an episode moves and waits as a mission does
HOVER_S = _LOOP.settle_s
SPEED_M_S = _LOOP.speed_m_s
MIN_MOVE_M = _LOOP.min_move_m
SHRINK = _LOOP.shrink


class CentringEnv(gym.Env[dict[str, Any], np.int64]):
    """Centre the named target in the camera view with the paper's 9 discrete moves (see the module doc)."""

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self,
        render_mode: str | None = None,
        max_steps: int = 20,
        epsilon_px: float | None = None,
        moves: str = "fixed",
        move_m: float = 0.3,
        instructions: str = "fixed",
        view_fraction: tuple[float, float] = (0.15, 0.8),
        distance_m: tuple[float, float] = (1.6, 2.6),
        yaw_deg: tuple[float, float] = (-8.0, 8.0),
        scene: str | dict[str, Any] | None = None,
        kinds: dict[str, Any] | None = None,
    ) -> None:
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        if max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {max_steps}")
        if moves not in MOVES:
            raise ValueError(f"moves must be one of {MOVES}, got {moves!r}")
        if not MIN_MOVE_M <= move_m <= 1.0:
            raise ValueError(f"move_m must be in [{MIN_MOVE_M}, 1.0], got {move_m}")
        if instructions not in CORPORA:
            raise ValueError(f"instructions must be one of {CORPORA}, got {instructions!r}")
        self.render_mode = render_mode
        self.max_steps = max_steps
        self.moves = moves
        self.move_m = move_m
        self.instructions = instructions
        self._scene = scene
        self._kinds = dict(kinds or {})
        self._templates = builtin_templates(instructions)
        self._random_start = {
            "view_fraction": list(view_fraction), "distance_m": list(distance_m), "yaw_deg": list(yaw_deg)
        }  # fmt: skip
        width = height = 224
        self.epsilon_px = float(epsilon_px) if epsilon_px is not None else default_epsilon_px(width)
        if not 0 < self.epsilon_px < width / 2:
            raise ValueError(f"epsilon_px must be in (0, {width / 2:g}), got {epsilon_px}")
        self.observation_space = spaces.Dict({
            "image": spaces.Box(0, 255, shape=(height, width, 3), dtype=np.uint8),
            "instruction": spaces.Text(
                max_length=MAX_INSTRUCTION_CHARS, min_length=1, charset="".join(sorted(INSTRUCTION_CHARSET))
            ),
        })  # fmt: skip
        self.action_space = spaces.Discrete(len(ALL_ACTIONS))
        self._stack: ExitStack | None = None
        self._sim: SimWorld | None = None
        self._image: np.ndarray | None = None
        self._image_width = width
        self._info_offset: tuple[float, float] | None = None
        self._instruction = ""
        self._info: dict[str, Any] = {}
        self._schedule = MoveSchedule(move_m, MIN_MOVE_M, SHRINK)
        self._steps = 0
        self._done = True

    # -- Gymnasium API ---------------------------------------------------------------------------

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[dict[str, Any], dict[str, Any]]:
        super().reset(seed=seed)
        options = dict(options or {})
        unknown = set(options) - {"scene_seed", "target_kind", "start", "instruction"}
        if unknown:
            raise ValueError(
                f"unknown reset options {sorted(unknown)}: use scene_seed, target_kind, start, instruction"
            )
        mission = self._mission(options)
        instruction = options.get("instruction")
        self._close_world()
        self._stack = ExitStack()
        try:
            self._sim = self._stack.enter_context(open_sim_world(mission))
            self._sim.vehicle.connect()
            take_off_to_start(self._sim.vehicle, mission.takeoff_altitude_m, self._sim.place_at_start)
        except BaseException:
            self._close_world()
            raise
        kind = self._sim.world.scene.target_kind
        if instruction is None:
            template = self._templates[int(self.np_random.integers(len(self._templates)))]
            instruction = fill(template, kind)
        self._instruction = _checked_instruction(instruction)
        self._schedule = MoveSchedule(self.move_m, MIN_MOVE_M, SHRINK)
        self._steps = 0
        self._done = False
        offset = self._observe()
        self._info = {
            "scene_seed": mission.scene.seed,
            "target_kind": kind,
            "start": self._sim.start.model_dump(),
            "epsilon_px": self.epsilon_px,
            "instruction": self._instruction,
        }
        return self._observation(), self._step_info(offset, None)

    def step(self, action: Any) -> tuple[dict[str, Any], float, bool, bool, dict[str, Any]]:
        if self._sim is None or self._done:
            raise RuntimeError("step() before reset() or after the episode ended: call reset()")
        if not self.action_space.contains(action):
            raise ValueError(f"action must be an integer in [0, {self.action_space.n}), got {action!r}")
        before = self._error(self._info_offset)
        chosen = Action.from_index(int(action))
        vehicle = self._sim.vehicle
        if chosen.is_none:
            vehicle.hold()
            vehicle.sleep(HOVER_S)
        else:
            if self.moves == "fixed":
                right_m, up_m = self._schedule.lengths_for(chosen)
            else:
                sx, sz = chosen.direction()
                right_m, up_m = sx * self.move_m, sz * self.move_m
            fly_offset(vehicle, right_m, up_m, SPEED_M_S)
        self._steps += 1
        offset = self._observe()
        reward = -STEP_COST
        outcome = None
        if offset is None:
            reward -= LOST_PENALTY
            outcome = "target_lost"
        else:
            reward += (before - self._error(offset)) / (self._image_width / 2.0)
            if within(offset[0], offset[1], self.epsilon_px):
                reward += CENTRED_BONUS
                outcome = "centred"
        terminated = outcome is not None
        truncated = not terminated and self._steps >= self.max_steps
        if truncated:
            outcome = "max_steps"
        self._done = terminated or truncated
        return self._observation(), float(reward), terminated, truncated, self._step_info(offset, outcome)

    def render(self) -> np.ndarray | None:
        """`rgb_array`: the newest camera frame with the image centre and the ε box drawn in."""
        if self.render_mode != "rgb_array" or self._image is None:
            return None
        image = self._image.copy()
        h, w = image.shape[:2]
        cx, cy, eps = w // 2, h // 2, round(self.epsilon_px)
        colour = np.array([255, 255, 0], dtype=np.uint8)
        top, bottom = max(cy - eps, 0), min(cy + eps, h - 1)
        left, right = max(cx - eps, 0), min(cx + eps, w - 1)
        image[top, left : right + 1] = colour
        image[bottom, left : right + 1] = colour
        image[top : bottom + 1, left] = colour
        image[top : bottom + 1, right] = colour
        image[cy, cx] = colour
        return image

    def close(self) -> None:
        self._close_world()
        super().close()

    # -- internals -------------------------------------------------------------------------------

    def _mission(self, options: dict[str, Any]) -> Mission:
        rng = self.np_random
        scene_seed = options.get("scene_seed")
        if scene_seed is None:
            scene_seed = int(rng.integers(0, 2**31 - 1))
        kind = options.get("target_kind")
        start = options.get("start")
        if start is None:
            start = {"random": {"seed": int(rng.integers(0, 2**31 - 1)), **self._random_start}}
        return parse_mission(
            {
                "name": "gym-centring",
                "kinds": self._kinds,
                "scene": {"seed": int(scene_seed), "config": self._scene},
                "target_kind": kind,
                "start": start,
                "vehicle": "sim",
                "planner": "classic",
                "epsilon_px": self.epsilon_px,
                "max_steps": self.max_steps,
            },
            source="CentringEnv.reset(options)",
        )

    def _observe(self) -> tuple[float, float] | None:
        assert self._sim is not None
        self._image = self._sim.camera.read().image
        self._image_width = self._image.shape[1]
        self._info_offset = self._sim.truth_offset()
        return self._info_offset

    def _error(self, offset: tuple[float, float] | None) -> float:
        """max(|du|, |dv|) in pixels; out of view counts as the half width."""
        if offset is None:
            return self._image_width / 2.0
        return max(abs(offset[0]), abs(offset[1]))

    def _observation(self) -> dict[str, Any]:
        assert self._image is not None
        return {"image": self._image, "instruction": self._instruction}

    def _step_info(self, offset: tuple[float, float] | None, outcome: str | None) -> dict[str, Any]:
        assert self._sim is not None
        return {
            **copy.deepcopy(self._info),  # a fresh dict every call: callers keep them
            "offset_px": None if offset is None else (float(offset[0]), float(offset[1])),
            "centred": offset is not None and within(offset[0], offset[1], self.epsilon_px),
            "outcome": outcome,
            "steps": self._steps,
            "sim_time_s": self._sim.vehicle.time_s(),
        }

    def _close_world(self) -> None:
        stack, self._stack, self._sim = self._stack, None, None
        if stack is not None:
            stack.close()


def _checked_instruction(text: object) -> str:
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"instruction must be a non-empty string, got {text!r}")
    text = text.strip()
    if len(text) > MAX_INSTRUCTION_CHARS:
        raise ValueError(f"instruction longer than {MAX_INSTRUCTION_CHARS} characters")
    odd = sorted(set(text) - INSTRUCTION_CHARSET)
    if odd:
        raise ValueError(f"instruction holds characters outside the observation's charset: {odd}")
    return text


if ENV_ID not in gym.registry:
    gym.register(id=ENV_ID, entry_point="controller.evaluation.gym_env:CentringEnv")
