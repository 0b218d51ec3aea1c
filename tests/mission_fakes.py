"""Fakes for unit tests of the centring loop and the mission runner (not for anything else).

With `fake_vehicle.FakeVehicle.at_pose` (a kinematic point in front of the target),
`FakeCamera` returns blank frames and `FakeDetector` derives the target's pixel position
from the fake vehicle's position by a pinhole relation, so the loop can be run
closed-loop without physics or rendering (`FakeMultiTargetDetector`: several targets on
the fake wall, with their truth as a simulator kit gives it). `FakePlanner` replays a
script of actions.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np
from fake_vehicle import FakeVehicle

from controller.missions.truth import TrueTarget
from controller.planning.actions import ALL_ACTIONS, Action
from controller.planning.planners import Observation, Plan
from perception.camera import Camera
from perception.types import Detection, Frame

IMAGE_SIZE = 224
PX_PER_M = 97.0  # a 60° camera 2 m from the wall: fx / distance = 194 / 2


class FakeCamera(Camera):
    """Blank RGB frames, numbered; each differs in one pixel (a real camera's pictures never repeat)."""

    def __init__(self, size: int = IMAGE_SIZE) -> None:
        self.size = size
        self.count = 0
        self.closed = False

    def read(self, timeout_s: float | None = None) -> Frame:
        image = np.zeros((self.size, self.size, 3), np.uint8)
        image.reshape(-1)[self.count % image.size] = 1 + self.count // image.size % 255
        frame = Frame(image, float(self.count), self.count)
        self.count += 1
        return frame

    def close(self) -> None:
        self.closed = True


class FakeDetector:
    """The target at (0 east, 0 up) seen from the fake vehicle; None outside the image or on a told miss."""

    def __init__(
        self,
        vehicle: FakeVehicle,
        misses: Iterable[int] = (),
        size: int = IMAGE_SIZE,
        bias_px: tuple[float, float] = (0.0, 0.0),
    ) -> None:
        self.vehicle = vehicle
        self.size = size
        self.misses = set(misses)  # call numbers (0-based) that return None
        self.bias_px = bias_px  # a detector error: added to the true centre
        self.calls = 0

    def truth_offset(self) -> tuple[float, float]:
        """(du, dv): the drone right of the target puts the target left in the image, and so on."""
        return -self.vehicle.east_m * PX_PER_M, self.vehicle.up_m * PX_PER_M

    def detect(self, image: np.ndarray) -> Detection | None:
        call, self.calls = self.calls, self.calls + 1
        du, dv = self.truth_offset()
        u, v = self.size / 2 + du + self.bias_px[0], self.size / 2 + dv + self.bias_px[1]
        if call in self.misses or not (0 <= u < self.size and 0 <= v < self.size):
            return None
        return Detection((u - 10, v - 10, u + 10, v + 10), (u, v), 0.9, "gauge")


class FakePlanner:
    """Replays `script` (action indices), then repeats its last entry; scores = index distances."""

    name = "fake"

    def __init__(self, script: Iterable[int] | Callable[[Observation], int]) -> None:
        self.script = script if callable(script) else list(script)
        self.calls = 0

    def plan(self, observation: Observation) -> Plan:
        if callable(self.script):
            index = self.script(observation)
        else:
            index = self.script[min(self.calls, len(self.script) - 1)]
        self.calls += 1
        action: Action = ALL_ACTIONS[index]
        return Plan(action, tuple(float(abs(i - index)) for i in range(len(ALL_ACTIONS))))


@dataclass(frozen=True)
class WallTarget:
    kind: str
    attribute: str
    east_m: float  # right of the centred pose's target
    up_m: float
    confidence: float


class FakeMultiTargetDetector:
    """Several targets on the fake wall seen from the fake vehicle (pinhole, `PX_PER_M`), strongest first.

    `gone_after` (call number) hides every target from then on: a target seen, then lost.
    """

    def __init__(
        self, vehicle: FakeVehicle, targets: list[WallTarget], gone_after: int | None = None
    ) -> None:
        self.vehicle = vehicle
        self.targets = targets
        self.gone_after = gone_after
        self.calls = 0

    def detect_all(self, image: np.ndarray) -> list[Detection]:
        call, self.calls = self.calls, self.calls + 1
        if self.gone_after is not None and call >= self.gone_after:
            return []
        found = []
        for t in self.targets:
            u = IMAGE_SIZE / 2 + (t.east_m - self.vehicle.east_m) * PX_PER_M
            v = IMAGE_SIZE / 2 + (self.vehicle.up_m - t.up_m) * PX_PER_M
            if 0 <= u < IMAGE_SIZE and 0 <= v < IMAGE_SIZE:
                box = (u - 10, v - 10, u + 10, v + 10)
                found.append(Detection(box, (u, v), t.confidence, t.kind, t.attribute))
        return sorted(found, key=lambda d: -d.confidence)

    def detect(self, image: np.ndarray) -> Detection | None:
        found = self.detect_all(image)
        return found[0] if found else None

    def offset_px(self, target: WallTarget) -> tuple[float, float] | None:
        """Where `target` is from the image centre now (None: out of the image)."""
        du = (target.east_m - self.vehicle.east_m) * PX_PER_M
        dv = (self.vehicle.up_m - target.up_m) * PX_PER_M
        inside = abs(du) < IMAGE_SIZE / 2 and abs(dv) < IMAGE_SIZE / 2
        return (du, dv) if inside else None

    def truth(self) -> list[TrueTarget]:
        """Every target's truth (the first is the scene's named one), as a simulator kit gives it."""
        return [TrueTarget(t.kind, t.attribute, self.offset_px(t)) for t in self.targets]
