"""StreamCamera against a real MJPEG server over loopback, a video file and bad sources."""

from __future__ import annotations

import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
import pytest

from perception.errors import CameraClosedError, CameraOpenError, CameraStreamEndedError, CameraTimeoutError
from perception.stream_camera import StreamCamera
from sim_world.rendering.mjpeg import MjpegServer

PORT = 18010
BITS = 8
SIZE = 96


def counter_image(n: int) -> np.ndarray:
    """A frame whose number is drawn as 8 black/white stripes (robust to JPEG)."""
    img = np.zeros((SIZE, SIZE, 3), np.uint8)
    stripe = SIZE // BITS
    for bit in range(BITS):
        if (n >> bit) & 1:
            img[:, bit * stripe : (bit + 1) * stripe] = 255
    return img


def read_counter(img: np.ndarray) -> int:
    stripe = img.shape[1] // BITS
    means = [img[:, b * stripe + 2 : (b + 1) * stripe - 2].mean() for b in range(BITS)]
    return sum(1 << b for b, m in enumerate(means) if m > 128)


@contextmanager
def publishing(server: MjpegServer) -> Iterator[None]:
    """Publish frames numbered 100, 101, ... at ~100 Hz while the body runs (FFmpeg probes a few
    frames while opening, as a live camera provides)."""
    stop = threading.Event()

    def run() -> None:
        n = 0
        while not stop.is_set():
            server.publish(counter_image(100 + n % 100))
            n += 1
            stop.wait(0.01)

    thread = threading.Thread(target=run)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


def open_camera(server: MjpegServer, timeout_s: float) -> StreamCamera:
    """A camera on the server's stream, drained of the frames published while opening."""
    with publishing(server):
        cam = StreamCamera(server.stream_url, timeout_s=timeout_s, open_timeout_s=3.0)
    time.sleep(0.1)
    cam.read()
    return cam


def _wait_received(cam: StreamCamera, count: int, timeout_s: float = 3.0) -> None:
    deadline = time.monotonic() + timeout_s
    while cam.frames_received < count and time.monotonic() < deadline:
        time.sleep(0.01)


def test_counter_code_round_trips() -> None:
    assert [read_counter(counter_image(n)) for n in (0, 1, 77, 255)] == [0, 1, 77, 255]


def test_reads_newest_frame_and_skips_older_ones() -> None:
    with MjpegServer(port=PORT) as server, open_camera(server, timeout_s=1.0) as cam:
        received = cam.frames_received
        for n in range(1, 11):
            server.publish(counter_image(n))
            time.sleep(0.02)
        _wait_received(cam, received + 2)
        time.sleep(0.2)
        newest = cam.read()
        assert newest.image.shape == (SIZE, SIZE, 3)
        assert read_counter(newest.image) == 10  # the newest, not the next one queued
        assert cam.frames_received - received >= 2  # several arrived; the older were skipped
        with pytest.raises(CameraTimeoutError):  # no stale repeat of an old frame
            cam.read(timeout_s=0.3)
        server.publish(counter_image(11))
        after = cam.read()
        assert read_counter(after.image) == 11
        assert after.frame_number == newest.frame_number + 1


def test_stalled_stream_raises_within_timeout() -> None:
    with MjpegServer(port=PORT + 1) as server, open_camera(server, timeout_s=0.5) as cam:
        for _ in range(2):  # the first wait, then one while the reader reconnects
            start = time.monotonic()
            with pytest.raises(CameraTimeoutError, match=r"within 0\.5 s"):
                cam.read()
            assert 0.45 <= time.monotonic() - start < 0.8


def test_dropped_stream_times_out_then_reconnects() -> None:
    server = MjpegServer(port=PORT + 2)
    with open_camera(server, timeout_s=1.0) as cam:
        server.close()
        start = time.monotonic()
        with pytest.raises(CameraTimeoutError, match=r"dropped or stalled after .* reconnecting"):
            cam.read()
        assert time.monotonic() - start < 1.3
        with MjpegServer(port=PORT + 2) as again, publishing(again):
            frame = cam.read(timeout_s=3.0)
        assert read_counter(frame.image) >= 100
        assert cam.reconnects == 1


def test_dropped_stream_without_reconnect_ends() -> None:
    server = MjpegServer(port=PORT + 5)
    with publishing(server):
        cam = StreamCamera(server.stream_url, timeout_s=1.0, open_timeout_s=3.0, reconnect=False)
    server.close()
    with cam, pytest.raises(CameraStreamEndedError, match=str(PORT + 5)):
        for _ in range(50):
            cam.read()


def test_refused_url_fails_fast_naming_the_url() -> None:
    url = f"http://127.0.0.1:{PORT + 3}/stream.mjpg"  # nothing listens there
    start = time.monotonic()
    with pytest.raises(CameraOpenError, match=str(PORT + 3)):
        StreamCamera(url, open_timeout_s=2.0)
    assert time.monotonic() - start < 1.5


def test_silent_server_open_times_out() -> None:
    """A server that accepts the connection but never answers: open is bounded by open_timeout_s."""
    with socket.socket() as listener:
        listener.bind(("127.0.0.1", PORT + 4))
        listener.listen(1)
        url = f"http://127.0.0.1:{PORT + 4}/stream.mjpg"
        start = time.monotonic()
        with pytest.raises(CameraOpenError, match=str(PORT + 4)):
            StreamCamera(url, open_timeout_s=0.7)
        assert time.monotonic() - start < 2.0


def test_missing_file_and_read_after_close(tmp_path: Path) -> None:
    with pytest.raises(CameraOpenError, match="no such video file"):
        StreamCamera(str(tmp_path / "none.avi"))
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 50.0, (SIZE, SIZE))
    for n in range(10):
        writer.write(counter_image(n))
    writer.release()
    cam = StreamCamera(str(path), timeout_s=1.0, realtime_file=True)
    numbers = [read_counter(cam.read().image) for _ in range(3)]
    assert numbers == sorted(numbers) and numbers[0] <= 1  # paced at 50 fps: nothing skipped early
    cam.close()
    with pytest.raises(CameraClosedError):
        cam.read()


def test_video_file_ends_with_stream_ended(tmp_path: Path) -> None:
    path = tmp_path / "short.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 100.0, (SIZE, SIZE))
    for n in range(5):
        writer.write(counter_image(n))
    writer.release()
    with StreamCamera(str(path), timeout_s=1.0) as cam:
        seen = []
        with pytest.raises(CameraStreamEndedError, match="end of file after 5 frames"):
            while True:
                seen.append(read_counter(cam.read().image))
        assert seen[-1] == 4


@pytest.mark.parametrize("stamped", [False, True])
def test_a_stream_whose_source_has_exited_ends_at_once_instead_of_waiting_out_the_timeout(
    stamped: bool,
) -> None:
    alive = True
    server = MjpegServer(port=0)
    try:
        with publishing(server):
            cam = StreamCamera(
                server.stream_url,
                timeout_s=5.0,
                open_timeout_s=3.0,
                scene_stamps=stamped,
                source_alive=lambda: alive,
            )
            cam.read()
    finally:
        alive = False  # the simulator serving it has exited, and its stream with it
        server.close()
    started = time.monotonic()
    with cam, pytest.raises(CameraStreamEndedError, match="source has exited"):
        while True:  # frames already in hand first, then the end
            cam.read()
    assert time.monotonic() - started < 2.0  # not the 5 s read timeout
