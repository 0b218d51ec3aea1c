"""Research: a picture as a stream camera receives it from the simulated vehicle's MJPEG stream.

The simulated vehicles send JPEG at `VideoConfig`'s quality with OpenCV's default 4:2:0 chroma (one
colour for each 2×2 pixels, as most cameras' streams; H.264 in its common profiles does the same), and
the stream camera decodes each with `perception.mjpeg_http.decode_jpeg`. A trim 1–2 px wide keeps its
luma there but shares its chroma with its neighbours, so figures measured on lossless renders overstate
the colour a stream gives (`perception.attributes`). `as_streamed` makes the same round trip in memory,
byte for byte what the MJPEG server serves (tests/test_perception_bench_accuracy.py), for
`dronectl bench perception` and `dronectl evaluate --with-detector --through-stream`.
"""

from __future__ import annotations

import cv2
import numpy as np

from perception.mjpeg_http import decode_jpeg
from sim_world.rendering.mjpeg import encode_jpeg
from sim_world.rendering.video import VideoConfig

STREAM_JPEG_QUALITY = VideoConfig().jpeg_quality
"""The simulated vehicle's MJPEG stream's JPEG quality (`sim_world.rendering.video.VideoConfig`)."""


def as_streamed(image_rgb: np.ndarray, quality: int = STREAM_JPEG_QUALITY) -> np.ndarray:
    """An RGB picture as a stream camera holds it after the simulated stream: encoded as the MJPEG
    server encodes a frame, decoded as `perception.mjpeg_http` decodes one."""
    bgr = decode_jpeg(encode_jpeg(image_rgb, quality))
    if bgr is None or bgr.size == 0:
        raise ValueError(f"a picture of shape {np.shape(image_rgb)} did not come back through JPEG")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
