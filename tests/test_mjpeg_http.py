"""Scene stamps from a simulator's stream to the loop's fresh frame.

The render process stamps each frame with when its pose was read; the MJPEG server sends the stamp with
each part; `StreamCamera(scene_stamps=True)` reads the stream part by part (`perception.mjpeg_http`, the
JPEG decoded by OpenCV) and hands the stamp on as `Frame.scene_s`; `read_fresh` then takes the first frame
of the scene as it was at a moment, by the stamp, and by arrival time from a camera that stamps nothing.
The parser is also fed broken and hostile bytes directly."""

from __future__ import annotations

import contextlib
import io
import socket
import threading
import time

import numpy as np
import pytest

from drone_inspect_core.video_stamps import SCENE_STAMP_HEADER, parse_scene_stamp
from perception.errors import CameraOpenError
from perception.fresh_frame import is_fresh, read_fresh
from perception.mjpeg_http import (
    MAX_BAD_PARTS,
    MAX_PART_BYTES,
    MjpegHttpCapture,
    MjpegParts,
    MjpegPullCapture,
    MjpegStreamError,
    boundary_of,
    jpeg_size,
)
from perception.stream_camera import StreamCamera
from perception.types import Frame
from sim_world.rendering.mjpeg import MjpegServer
from tests.test_perception_stream_camera import counter_image, read_counter


def _publish_stamped(server: MjpegServer, stop: threading.Event, stamps: dict[int, float]) -> None:
    n = 0
    while not stop.is_set():
        stamp = 1000.0 + n * 0.25
        stamps[100 + n % 100] = stamp
        server.publish(counter_image(100 + n % 100), scene_s=stamp)
        n += 1
        stop.wait(0.02)


@pytest.mark.parametrize("stamped", [True, False])
def test_each_frame_keeps_the_scene_stamp_its_part_carried_and_ffmpeg_still_reads_the_stream(
    stamped: bool,
) -> None:
    stamps: dict[int, float] = {}
    stop = threading.Event()
    with MjpegServer(port=0) as server:
        thread = threading.Thread(target=_publish_stamped, args=(server, stop, stamps))
        thread.start()
        try:
            with StreamCamera(
                server.stream_url, timeout_s=2.0, open_timeout_s=3.0, scene_stamps=stamped
            ) as cam:
                frames = [cam.read() for _ in range(5)]
        finally:
            stop.set()
            thread.join()
    numbers = [read_counter(f.image) for f in frames]
    assert all(100 <= n < 200 for n in numbers) and numbers == sorted(numbers)  # decoded, in order
    if stamped:  # each frame with the stamp its own part carried, not another's
        assert [f.scene_s for f in frames] == [stamps[n] for n in numbers]
    else:  # FFmpeg reads the same stream, extra header and all, and knows no stamp
        assert all(f.scene_s is None for f in frames)


def test_scene_stamps_only_from_an_http_stream_and_a_wrong_url_says_why() -> None:
    with pytest.raises(ValueError, match="http://"):
        StreamCamera("rtsp://127.0.0.1:1/x", scene_stamps=True)
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    with pytest.raises(CameraOpenError, match=r"refused|stream"):
        StreamCamera(f"http://127.0.0.1:{port}/stream.mjpg", open_timeout_s=1.0, scene_stamps=True)
    with MjpegServer(port=0) as server:
        server.publish(counter_image(1))
        with pytest.raises(CameraOpenError, match="not an MJPEG stream"):  # /frame.jpg is one JPEG
            StreamCamera(
                server.stream_url.replace("stream.mjpg", "frame.jpg"), open_timeout_s=1.0, scene_stamps=True
            )


def _parts(body: bytes, boundary: str = "b") -> MjpegParts:
    return MjpegParts(
        io.BufferedReader(io.BytesIO(body)), boundary_of(f"multipart/x-mixed-replace; boundary={boundary}")
    )


def test_the_parser_reads_parts_with_and_without_a_length_and_refuses_hostile_ones() -> None:
    jpeg = b"\xff\xd8 some bytes\r\n--b but not a boundary line \xff\xd9"
    stream = (
        b"preamble\r\n--b\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n"
        b"X-Scene-Monotonic: 12.5\r\n\r\n%s\r\n"
        b"--b\r\nContent-Type: image/jpeg\r\n\r\nno length\r\nsecond line\r\n--b\r\n"
        b"Content-Length: 3\r\n\r\nabc\r\n--b--\r\n"
    ) % (len(jpeg), jpeg)
    parts = _parts(stream)
    headers, body = parts.next_part()
    assert body == jpeg and parse_scene_stamp(headers[SCENE_STAMP_HEADER.lower()]) == 12.5
    assert parts.next_part() == ({"content-type": "image/jpeg"}, b"no length\r\nsecond line")
    assert parts.next_part()[1] == b"abc"  # the boundary the part before consumed
    with pytest.raises(MjpegStreamError, match="closing boundary"):
        parts.next_part()

    hostile = {
        b"--b\r\nContent-Length: %d\r\n\r\n" % (MAX_PART_BYTES + 1): "at most",
        b"--b\r\nContent-Length: -5\r\n\r\n": "at most",
        b"--b\r\nContent-Length: lots\r\n\r\n": "not a number",
        b"--b\r\nContent-Length: 100\r\n\r\nshort": "inside a part",
        b"--b\r\n" + b"X: y\r\n" * 40 + b"\r\n": "more than",
        b"--b\r\nX: " + b"y" * 10000 + b"\r\n": "over",
        b"x" * 100: "the stream ended",
        (b"junk " * 20 + b"\r\n") * 20000: "no part boundary",
    }
    for data, message in hostile.items():
        with pytest.raises(MjpegStreamError, match=message):
            _parts(data).next_part()
    for content_type in ("image/jpeg", "multipart/x-mixed-replace", "multipart/x-mixed-replace; boundary="):
        with pytest.raises(MjpegStreamError):
            boundary_of(content_type)
    assert [parse_scene_stamp(v) for v in ("3.25", " 7 ", "nan", "-1", "inf", "x", None)] == [
        3.25,
        7.0,
        None,
        None,
        None,
        None,
        None,
    ]


def test_a_part_that_does_not_decode_is_skipped_and_the_next_one_read() -> None:
    """A server (a raw socket, named so) that sends a corrupt part, then a good one."""
    import cv2

    good = cv2.imencode(".jpg", counter_image(42))[1].tobytes()
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)

    def serve() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.recv(4096)
            conn.sendall(b"HTTP/1.0 200 OK\r\nContent-Type: multipart/x-mixed-replace;boundary=xx\r\n\r\n")
            for body, stamp in ((b"\xff\xd8 not a picture", b"1.0"), (good, b"2.0")):
                conn.sendall(
                    b"--xx\r\nContent-Length: %d\r\nX-Scene-Monotonic: %s\r\n\r\n%s\r\n"
                    % (len(body), stamp, body)
                )
            time.sleep(0.5)

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        url = f"http://127.0.0.1:{listener.getsockname()[1]}/stream.mjpg"
        with StreamCamera(url, timeout_s=2.0, open_timeout_s=2.0, scene_stamps=True, reconnect=False) as cam:
            frame = cam.read()
    finally:
        thread.join()
        listener.close()
    assert read_counter(frame.image) == 42 and frame.scene_s == 2.0


def test_a_stream_of_parts_that_never_decode_is_refused_not_read_forever() -> None:
    """A server (a raw socket, named so) whose parts are all garbage: opening fails, saying so."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)
    sent = threading.Event()

    def serve() -> None:
        conn, _ = listener.accept()
        with conn:
            conn.recv(4096)
            conn.sendall(b"HTTP/1.0 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary=xx\r\n\r\n")
            with contextlib.suppress(OSError):
                for _ in range(MAX_BAD_PARTS + 5):
                    conn.sendall(b"--xx\r\nContent-Length: 4\r\n\r\njunk\r\n")
            sent.set()
            time.sleep(1.0)

    thread = threading.Thread(target=serve)
    thread.start()
    try:
        url = f"http://127.0.0.1:{listener.getsockname()[1]}/stream.mjpg"
        with pytest.raises(CameraOpenError, match="no picture OpenCV can decode"):
            StreamCamera(url, timeout_s=2.0, open_timeout_s=3.0, scene_stamps=True, reconnect=False)
    finally:
        thread.join()
        listener.close()
    assert sent.is_set()


def _raw_server(parts: list[bytes], pause_s: float = 0.0) -> tuple[str, threading.Thread, socket.socket]:
    """A server (a raw socket, named so) that answers one GET with an MJPEG header, then sends `parts`,
    each `pause_s` after the last."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(1)

    def serve() -> None:
        conn, _ = listener.accept()
        with conn, contextlib.suppress(OSError):
            conn.recv(4096)
            conn.sendall(b"HTTP/1.0 200 OK\r\nContent-Type: multipart/x-mixed-replace; boundary=xx\r\n\r\n")
            for part in parts:
                time.sleep(pause_s)
                conn.sendall(part)
            time.sleep(0.5)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return f"http://127.0.0.1:{listener.getsockname()[1]}/stream.mjpg", thread, listener


def test_a_part_announcing_a_huge_picture_is_not_decoded_and_a_trickle_does_not_hold_the_open() -> None:
    import cv2

    good = cv2.imencode(".jpg", counter_image(7))[1].tobytes()
    assert jpeg_size(good) == (96, 96)
    sof = good.index(b"\xff\xc0")  # the baseline frame header: precision, then height and width
    huge = good[: sof + 5] + (20000).to_bytes(2, "big") * 2 + good[sof + 9 :]
    assert jpeg_size(huge) == (20000, 20000)  # 400 M pixels (1.2 GB decoded), announced in 4 bytes
    part = b"--xx\r\nContent-Length: %d\r\n\r\n%s\r\n"
    url, thread, listener = _raw_server([part % (len(huge), huge), part % (len(good), good)])
    try:
        capture = MjpegHttpCapture(url, open_timeout_s=2.0, read_timeout_s=2.0)
        ok, bgr = capture.read()
        assert ok and read_counter(bgr[:, :, ::-1]) == 7  # the huge one skipped, the next one read
        assert capture.oversized == 1 and capture.skipped == 1  # refused by its header, never decoded
        capture.release()
    finally:
        thread.join()
        listener.close()

    trickle = [bytes([b]) for b in b"--xx\r\nContent-Length: 100000\r\n\r\n" * 10]
    url, thread, listener = _raw_server(trickle, pause_s=0.2)  # a byte every 0.2 s: no read times out
    started = time.monotonic()
    try:
        with pytest.raises(CameraOpenError):
            StreamCamera(url, timeout_s=2.0, open_timeout_s=1.0, scene_stamps=True, reconnect=False)
        assert time.monotonic() - started < 3.0
    finally:
        listener.close()


class FakeCamera:
    """Hands out the frames it is given, one per read (a fake for the freshness rule alone)."""

    def __init__(self, frames: list[Frame]) -> None:
        self.frames, self.reads = frames, 0

    def read(self, timeout_s: float | None = None) -> Frame:
        self.reads += 1
        if len(self.frames) == 1:  # the last one again, a frame period later: a stream that stopped moving
            time.sleep(0.01)
            return self.frames[0]
        return self.frames.pop(0)


def _frame(n: int, arrived_s: float, scene_s: float | None) -> Frame:
    return Frame(np.zeros((2, 2, 3), np.uint8), arrived_s, n, scene_s)


def test_a_fresh_frame_is_chosen_by_its_stamp_when_it_has_one_else_by_arrival_and_margin() -> None:
    now = time.monotonic()
    # Stamped: a frame that arrived late but shows the scene from before `now` is stale; one stamped at
    # `now` is fresh at once, with no wall-time margin.
    stamped = FakeCamera(
        [_frame(0, now + 0.5, now - 0.01), _frame(1, now + 0.01, now), _frame(2, now + 1, now + 1)]
    )
    assert read_fresh(stamped, now, margin_s=0.1, timeout_s=2.0).frame_number == 1 and stamped.reads == 2
    # Unstamped: the margin counts from arrival.
    plain = FakeCamera([_frame(0, now + 0.05, None), _frame(1, now + 0.1, None), _frame(2, now + 1, None)])
    assert read_fresh(plain, now, margin_s=0.1, timeout_s=2.0).frame_number == 1
    assert is_fresh(_frame(0, now, now), now, 0.1) and not is_fresh(_frame(0, now, None), now, 0.1)
    # Bounded: a stream whose frames never get fresh gives its newest once the wait is over.
    old = FakeCamera([_frame(i, now - 10 + i, None) for i in range(3)])
    started = time.monotonic()
    assert read_fresh(old, time.monotonic(), margin_s=0.0, timeout_s=0.2).frame_number == 2
    assert time.monotonic() - started < 1.0


def _answering_server(
    answers: list[bytes], pause_s: float = 0.0
) -> tuple[str, threading.Thread, socket.socket]:
    """A server (a raw socket, named so) that answers each of len(answers) GETs, one connection each, with
    the next raw answer (sent a byte every `pause_s` when given)."""
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(4)

    def serve() -> None:
        for answer in answers:
            try:
                conn, _ = listener.accept()
            except OSError:
                return
            with conn, contextlib.suppress(OSError):
                conn.recv(4096)
                if pause_s:
                    for byte in answer:
                        conn.sendall(bytes([byte]))
                        time.sleep(pause_s)
                else:
                    conn.sendall(answer)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    return f"http://127.0.0.1:{listener.getsockname()[1]}/stream.mjpg", thread, listener


def _jpeg_answer(body: bytes, stamp: bytes = b"", length: bytes | None = None) -> bytes:
    head = b"HTTP/1.0 200 OK\r\nContent-Type: image/jpeg\r\nContent-Length: %s\r\n" % (
        length or b"%d" % len(body)
    )
    return head + (b"X-Scene-Monotonic: %s\r\n" % stamp if stamp else b"") + b"\r\n" + body


def test_pictures_on_demand_skip_what_does_not_decode_and_refuse_what_is_too_big_or_too_slow() -> None:
    import cv2

    good = cv2.imencode(".jpg", counter_image(9))[1].tobytes()
    sof = good.index(b"\xff\xc0")
    huge = good[: sof + 5] + (20000).to_bytes(2, "big") * 2 + good[sof + 9 :]
    url, thread, listener = _answering_server(
        [
            _jpeg_answer(good, b"1.0"),
            _jpeg_answer(huge, b"2.0"),
            _jpeg_answer(b"junk"),
            _jpeg_answer(good, b"3.0"),
        ]
    )
    try:
        capture = MjpegPullCapture(url, open_timeout_s=2.0, read_timeout_s=2.0)  # the first answer opens it
        assert capture.isOpened()
        ok, bgr = capture.read()  # the huge one and the junk are skipped, each asked again
        assert ok and read_counter(bgr[:, :, ::-1]) == 9 and capture.scene_s == 3.0
        assert (capture.oversized, capture.skipped) == (1, 2)
        capture.release()
        assert capture.read() == (False, None)
    finally:
        thread.join(2.0)
        listener.close()

    url, thread, listener = _answering_server([_jpeg_answer(good, length=b"%d" % (MAX_PART_BYTES + 1))])
    try:
        capture = MjpegPullCapture(url, open_timeout_s=2.0, read_timeout_s=2.0)
        assert not capture.isOpened() and "at most" in (capture.error or "")
    finally:
        listener.close()

    url, thread, listener = _answering_server([_jpeg_answer(good)], pause_s=0.05)  # a byte every 50 ms
    started = time.monotonic()
    try:
        with pytest.raises(CameraOpenError):
            StreamCamera(
                url, timeout_s=2.0, open_timeout_s=1.0, scene_stamps=True, on_demand=True, reconnect=False
            )
        assert time.monotonic() - started < 3.0
    finally:
        listener.close()
