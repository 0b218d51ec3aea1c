"""The in-process simulated camera: renders the world's forward camera at the drone's current pose.

Rendering is synchronous, so a frame is always the newest: `read()` renders the
state the world is in now. Typed against a small protocol rather than
`sim_world.World`, so that importing perception never imports PyBullet.
"""

from __future__ import annotations

import time
from typing import Any, Protocol

from perception.camera import Camera
from perception.errors import CameraClosedError
from perception.types import Frame


class RenderingWorld(Protocol):
    """What the simulated camera needs of `sim_world.World`."""

    def render(self, with_seg: bool = True) -> Any:
        """A `Render` with `.rgb` (H, W, 3) uint8 and `.seg`."""
        ...


class SimCamera(Camera):
    """Frames rendered from a `sim_world.World`; `last_render` keeps the depth and segmentation.

    `with_seg=False` skips the segmentation mask (a little faster); keep it when a
    `TruthDetector` should account for occlusion.
    """

    def __init__(self, world: RenderingWorld, with_seg: bool = True) -> None:
        self._world = world
        self._with_seg = with_seg
        self._frames = 0
        self._closed = False
        self.last_render: Any = None

    def read(self, timeout_s: float | None = None) -> Frame:
        """Render now (rendering cannot stall, so the timeout is not needed)."""
        if self._closed:
            raise CameraClosedError("sim", "read() after close()")
        shown_s = time.monotonic()  # the world stands still while it renders in this thread
        render = self._world.render(with_seg=self._with_seg)
        self.last_render = render
        frame = Frame(
            image=render.rgb, timestamp_s=time.monotonic(), frame_number=self._frames, scene_s=shown_s
        )
        self._frames += 1
        return frame

    def close(self) -> None:
        """Forget the world (the world itself belongs to the caller)."""
        self._closed = True
        self.last_render = None
