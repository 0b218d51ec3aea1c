"""The detector interface and the simulator-truth detector.

`Detector.detect(image) -> Detection | None`. Two backends: `TruthDetector` (here;
reads the simulator's geometry and segmentation, for data generation and judging
only, never for deciding) and `image_detector.ImageDetector` (pixels alone, what
the controller uses on a real drone and in simulation alike; it also has
`detect_all(image) -> list[Detection]`, every target with its kind and attribute,
which the centring loop prefers where a detector has it).
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from perception.types import Detection


class Detector(Protocol):
    """Finds the inspection target in an RGB uint8 (H, W, 3) image."""

    def detect(self, image: np.ndarray) -> Detection | None: ...


def detect_all(detector: Detector, image: np.ndarray) -> tuple[Detection, ...]:
    """Every detection, strongest first: `detect_all` where the detector has it, else `detect`'s one."""
    every = getattr(detector, "detect_all", None)
    if callable(every):
        return tuple(every(image))
    detection = detector.detect(image)
    return () if detection is None else (detection,)


class TruthWorld(Protocol):
    """What the truth detector needs of `sim_world.World`."""

    scene: Any  # has .target_kind

    def target_truth(self, render: Any = None) -> Any:
        """A `TargetTruth` (centre_px, bbox_px, in_view, visible_fraction, ...)."""
        ...


class LastRender(Protocol):
    last_render: Any


class TruthDetector:
    """The target as the simulator knows it, at the world's current state.

    In the in-process loop the world does not move between a `SimCamera.read()` and
    `detect()`, so the truth matches the frame; the image itself is not looked at.
    With `camera` (a `SimCamera`), its last render's segmentation accounts for
    occlusion in `visible_fraction`, which becomes the confidence. Returns None
    when the target's centre is out of the image or nothing of it is visible.
    """

    def __init__(self, world: TruthWorld, camera: LastRender | None = None) -> None:
        self._world = world
        self._camera = camera

    def detect(self, image: np.ndarray) -> Detection | None:
        render = self._camera.last_render if self._camera is not None else None
        truth = self._world.target_truth(render)
        if not truth.in_view or truth.bbox_px is None or truth.visible_fraction <= 0.0:
            return None
        return Detection(
            bbox_px=tuple(float(x) for x in truth.bbox_px),  # type: ignore[arg-type]
            centre_px=(float(truth.centre_px[0]), float(truth.centre_px[1])),
            confidence=float(truth.visible_fraction),
            kind=str(self._world.scene.target_kind),
        )
