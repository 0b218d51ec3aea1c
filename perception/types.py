"""Value types shared by cameras, detectors and the centring test."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Frame:
    """One camera image.

    `image` is RGB uint8 (H, W, 3). `timestamp_s` is `time.monotonic()` when the frame
    came into hand (the reader thread's arrival time for a stream, the render time
    for the simulated camera), so `time.monotonic() - frame.timestamp_s` is its age.
    `frame_number` counts the frames this camera received, from 0; gaps mean frames
    were skipped to stay on the newest one. `scene_s`, when the source says it, is the
    `time.monotonic()` of this host at which the scene shown was current (a simulator's
    render process stamps each frame with when it read the pose it drew); None when
    unknown, as from any real camera.
    """

    image: np.ndarray
    timestamp_s: float
    frame_number: int
    scene_s: float | None = None

    @property
    def width(self) -> int:
        return int(self.image.shape[1])

    @property
    def height(self) -> int:
        return int(self.image.shape[0])


@dataclass(frozen=True)
class Detection:
    """A detected target in pixel coordinates (u right, v down, origin top-left corner).

    `centre_px` is the projection of the target face's centre (the point the
    controller centres), which under perspective need not be the middle of
    `bbox_px` = (u0, v0, u1, v1). `confidence` is in [0, 1]; `kind` is "gauge",
    "valve", "switchbox" or None when the detector does not classify; `attribute` is
    the trim colour's name (`drone_inspect_core.vocabulary`), None when not read;
    `attribute_doubt` how unsure that read is (`perception.attributes.ColourRead`: lower is a surer read;
    comparable between detections of one kind), None when not read.
    """

    bbox_px: tuple[float, float, float, float]
    centre_px: tuple[float, float]
    confidence: float
    kind: str | None = None
    attribute: str | None = None
    attribute_doubt: float | None = None
