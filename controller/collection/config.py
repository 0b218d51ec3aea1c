"""What a flown collection is asked to do: the vehicle and camera, the goal, the box, the counts, the limits.

`FlownCollectConfig` is built at the entry point (`dronectl collect --vehicle ...`) and checked in
`__post_init__`: a bad value is a `ValueError` whose message names the option, raised before anything
connects or takes off.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

from controller.missions.vehicles import SIM, SIMULATED_VEHICLES, simulator_speed_of
from drone_inspect_core.sim_speed import OFF_REAL_TIME_FRESH_FRAME_S, off_real_time, parse_sim_speed

GOAL_HERE, GOAL_SCENE = "here", "scene"
SIMULATED = tuple(v for v in SIMULATED_VEHICLES if v != SIM)
"""The vehicles a collection can start itself (the in-process `sim` has no MAVLink link to fly)."""
OnLoss = Literal["land", "return"]


@dataclass(frozen=True)
class Box3:
    """Half sizes of a box in the goal's heading frame: right/left, up/down, forward/back (metres)."""

    right_m: float
    up_m: float
    forward_m: float

    @classmethod
    def parse(cls, text: str, option: str) -> Box3:
        """`0.8` (every axis) or `0.8,0.6,0.4` (right, up, forward)."""
        try:
            values = [float(v) for v in text.split(",")]
        except ValueError:
            raise ValueError(f"{option} {text!r}: expected a number or three (right,up,forward)") from None
        if len(values) == 1:
            values *= 3
        if len(values) != 3:
            raise ValueError(f"{option} {text!r}: expected a number or three (right,up,forward)")
        box = cls(*values)
        if not all(math.isfinite(v) and v > 0 for v in values):
            raise ValueError(f"{option} {text!r}: every half size must be a number > 0")
        return box

    def contains(self, forward_m: float, right_m: float, up_m: float, slack_m: float = 0.0) -> bool:
        return (
            abs(right_m) <= self.right_m + slack_m
            and abs(up_m) <= self.up_m + slack_m
            and abs(forward_m) <= self.forward_m + slack_m
        )

    def as_list(self) -> list[float]:
        return [self.right_m, self.up_m, self.forward_m]


@dataclass(frozen=True)
class SimOptions:
    """The simulated world of a `sim-mavlink`, `px4-sitl` or `ardupilot-sitl` collection (ignored for a real
    vehicle)."""

    scene_file: Path | None = None
    scene_seed: int = 0
    sim_speed: float | str = "max"
    """sim-mavlink: simulated seconds per wall second, or "max"."""
    px4_dir: Path | None = None
    px4_speed: float | str = "max"
    ardupilot_dir: Path | None = None
    ardupilot_speed: float | str = "max"
    start_right_m: float = 0.4
    """The drone starts landed below a pose this far right of the centred one (it flies over, as an
    operator would, with `--goal scene`)."""
    start_distance_m: float = 2.0

    def __post_init__(self) -> None:
        parse_sim_speed(str(self.sim_speed))
        parse_sim_speed(str(self.px4_speed))
        parse_sim_speed(str(self.ardupilot_speed))
        if self.scene_seed < 0:
            raise ValueError(f"--scene-seed must be >= 0, got {self.scene_seed}")
        if not 0.8 <= self.start_distance_m <= 5.0:
            raise ValueError(f"--distance-from-wall must be in [0.8, 5] m, got {self.start_distance_m}")


@dataclass(frozen=True)
class Settling:
    """When a capture may be taken: speed and tilt under these for `hold_s`, within `timeout_s`."""

    speed_m_s: float = 0.06
    attitude_deg: float = 2.5
    yaw_error_deg: float = 2.0
    hold_s: float = 0.4
    timeout_s: float = 12.0
    position_tolerance_m: float = 0.05
    """Near enough to the planned pose to stop flying to it (the label is the capture's, not the plan's)."""


@dataclass(frozen=True)
class FlownCollectConfig:
    """Everything `collect_flown` needs; every field is checked here, before anything connects."""

    out_dir: Path
    vehicle: str
    camera: str | None
    kind: str
    goal: str
    """"here" (the current pose), "scene" (simulated vehicles: fly to the scene's centred pose first), or
    a goal file written by an earlier collection (`goal.json`)."""
    box: Box3 = field(default_factory=lambda: Box3(0.8, 0.6, 0.4))
    fence: Box3 = field(default_factory=lambda: Box3(1.5, 1.2, 1.0))
    goal_box_px: tuple[float, float, float, float] | None = None
    """The target's box in the goal image (x, y, w, h as given, stored as u0, v0, u1, v1); None: the
    detector finds it (a kind it knows)."""
    distance_m: float | None = None
    """The target's distance from the goal pose along the camera's axis; None: the forward rangefinder."""
    camera_file: Path | None = None
    kinds_file: Path | None = None
    """A kinds file (`kinds:` as a scene or mission file writes it) adding the kind collected: a target of
    one's own, named and given its words once (`controller.collection.inputs`)."""
    n_goal: int = 20
    n_per_sector: int = 20
    """Captures in each of the eight sectors and the centre class."""
    n_empty: int = 10
    block_size: int = 9
    test_every: int = 5
    """Every `test_every`-th time block of `block_size` captures is held out (split `test`)."""
    epsilon_px: float | None = None
    agree_px: float | None = None
    """The most the image-tracked and pose-derived offsets may differ (None: 10 % of the image width)."""
    max_speed_m_s: float = 0.5
    settling: Settling = field(default_factory=Settling)
    empty_yaw_deg: float = 50.0
    min_altitude_m: float = 0.4
    on_loss: OnLoss = "land"
    loss_wait_s: float = 5.0
    """A lost camera: hold this long for it to come back before `on_loss`."""
    resume: bool = False
    seed: int = 0
    sim: SimOptions = field(default_factory=SimOptions)
    progress: bool = True

    @property
    def simulator_speed(self) -> float | str | None:
        """The speed of the simulator this collection starts, as given (None: a real vehicle)."""
        sim = self.sim
        return simulator_speed_of(self.vehicle, sim.sim_speed, sim.px4_speed, sim.ardupilot_speed)

    @property
    def frame_lag_s(self) -> float:
        """How long after the drone settles a frame must arrive to show it settled: 0 at real time, else
        `OFF_REAL_TIME_FRESH_FRAME_S` (the camera's wall-time lag is more of the vehicle's clock)."""
        return OFF_REAL_TIME_FRESH_FRAME_S if off_real_time(self.simulator_speed) else 0.0

    def __post_init__(self) -> None:
        if not self.goal:
            raise ValueError(
                "--goal: say where the goal is: here, scene (a simulated vehicle) or a goal.json"
            )
        if not self.kind:
            raise ValueError(
                "--kind: name the target's kind (gauge, valve, switchbox, or one of yours: --kinds FILE)"
            )
        if self.out_dir is None or not str(self.out_dir):
            raise ValueError(
                "--out: give the dataset folder (new or empty; with --resume, the one to go on with)"
            )
        if self.vehicle in SIMULATED:
            if self.camera not in (None, "sim"):
                raise ValueError(
                    f"--camera: a {self.vehicle} vehicle brings its own camera; leave --camera out"
                )
        elif not self.camera:
            raise ValueError(
                "--camera: a real vehicle needs its camera's stream URL (http://..., rtsp://...)"
            )
        if self.goal == GOAL_SCENE and self.vehicle not in SIMULATED:
            raise ValueError(
                f"--goal scene needs a simulated vehicle ({', '.join(SIMULATED)}); fly a real one to the "
                "centred pose and use --goal here"
            )
        if self.distance_m is not None and not (math.isfinite(self.distance_m) and self.distance_m > 0):
            raise ValueError(f"--distance-m must be a distance > 0, got {self.distance_m:g}")
        for name in ("n_goal", "n_per_sector", "n_empty"):
            if getattr(self, name) < 0:
                raise ValueError(f"--{name.replace('_', '-')} must be >= 0, got {getattr(self, name)}")
        if self.n_goal < 1 or self.n_per_sector < 1:
            raise ValueError(
                "--n-goal and --n-per-sector must be >= 1 (goal images and sector images to train on)"
            )
        if self.block_size < 1 or self.test_every < 2:
            raise ValueError("--block-size must be >= 1 and --test-every >= 2")
        if not 0.05 <= self.max_speed_m_s <= 2.0:
            raise ValueError(f"--max-speed must be in [0.05, 2] m/s, got {self.max_speed_m_s:g}")
        if self.epsilon_px is not None and not self.epsilon_px > 0:
            raise ValueError(f"--epsilon-px must be > 0, got {self.epsilon_px:g}")
        if self.agree_px is not None and not self.agree_px > 0:
            raise ValueError(f"--agree-px must be > 0, got {self.agree_px:g}")
        if not 20.0 <= self.empty_yaw_deg <= 90.0:
            raise ValueError(f"--empty-yaw-deg must be in [20, 90], got {self.empty_yaw_deg:g}")
        if self.on_loss not in ("land", "return"):
            raise ValueError(f"--on-loss must be 'land' or 'return', got {self.on_loss!r}")
        margin = 0.25  # the geofence's breach margin and an overshoot: the box keeps clear of the fence
        for axis in ("right_m", "up_m", "forward_m"):
            box, fence = getattr(self.box, axis), getattr(self.fence, axis)
            if box + margin > fence:
                raise ValueError(
                    f"--box-m {self.box.as_list()} does not fit the geofence --fence-m "
                    f"{self.fence.as_list()}: {axis.removesuffix('_m')} {box:g} m + {margin} m margin "
                    f"> {fence:g} m"
                )
        if self.goal_box_px is not None:
            x, y, w, h = self.goal_box_px
            if not (w > 0 and h > 0 and x >= 0 and y >= 0):
                raise ValueError(
                    f"--goal-box {self.goal_box_px}: expected x,y,w,h with w, h > 0 inside the image"
                )

    @property
    def simulated(self) -> bool:
        return self.vehicle in SIMULATED
