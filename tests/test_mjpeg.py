"""The simulated vehicle's MJPEG server: endpoints, truth, input checks and clean shutdown."""

from __future__ import annotations

import json
import socket
import threading
import time
import urllib.error
import urllib.request

import cv2
import numpy as np
import pytest

from drone_inspect_core.video_stamps import SCENE_STAMP_HEADER
from sim_world.rendering.mjpeg import BOUNDARY, MjpegServer

PORT = 18000


def _get(url: str) -> tuple[int, dict[str, str], bytes]:
    try:
        with urllib.request.urlopen(url, timeout=3.0) as resp:
            return resp.status, dict(resp.headers), resp.read()
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers), exc.read()


def _image(value: int) -> np.ndarray:
    img = np.zeros((48, 64, 3), np.uint8)
    img[:, :, 0] = value  # red channel only: checks the RGB order survives the BGR encoder
    return img


def test_frame_endpoint_serves_latest_frame_and_number() -> None:
    with MjpegServer(port=PORT) as server:
        base = f"http://127.0.0.1:{server.port}"
        status, _, _ = _get(base + "/frame.jpg")
        assert status == 503  # nothing published yet
        assert server.publish(_image(40)) == 0
        assert server.publish(_image(200)) == 1
        status, headers, body = _get(base + "/frame.jpg")
        assert status == 200
        assert headers["Content-Type"] == "image/jpeg"
        assert headers["X-Frame-Number"] == "1"
        bgr = cv2.imdecode(np.frombuffer(body, np.uint8), cv2.IMREAD_COLOR)
        assert bgr.shape == (48, 64, 3)
        assert abs(int(bgr[..., 2].mean()) - 200) <= 3  # red, newest frame
        assert int(bgr[..., 0].max()) <= 8


def test_truth_endpoint_latest_and_by_frame() -> None:
    with MjpegServer(port=PORT + 1, truth_history=2) as server:
        base = f"http://127.0.0.1:{server.port}"
        for i in range(3):
            server.publish(_image(i), truth={"centre_px": [i, 2 * i]})
        status, _, body = _get(base + "/truth.json")
        assert status == 200
        assert json.loads(body) == {"frame_number": 2, "truth": {"centre_px": [2, 4]}}
        assert json.loads(_get(base + "/truth.json?frame=1")[2])["truth"] == {"centre_px": [1, 2]}
        assert _get(base + "/truth.json?frame=0")[0] == 404  # fell out of the 2-frame history
        assert _get(base + "/truth.json?frame=x")[0] == 400
        assert _get(base + "/nothing")[0] == 404


def test_stream_sends_multipart_jpeg_parts() -> None:
    with MjpegServer(port=PORT + 2) as server:
        server.publish(_image(10))
        with socket.create_connection(("127.0.0.1", server.port), timeout=3.0) as sock:
            sock.sendall(b"GET /stream.mjpg HTTP/1.0\r\n\r\n")
            data = b""
            while data.count(b"\xff\xd9") < 1:
                data += sock.recv(65536)
            server.publish(_image(20))
            while data.count(b"\xff\xd9") < 2:
                data += sock.recv(65536)
        head, _, rest = data.partition(b"\r\n\r\n")
        assert f"multipart/x-mixed-replace; boundary={BOUNDARY}".encode() in head
        assert rest.startswith(f"--{BOUNDARY}\r\nContent-Type: image/jpeg\r\n".encode())
        assert b"X-Frame-Number: 0" in rest and b"X-Frame-Number: 1" in rest


def test_publish_rejects_bad_images_and_truth() -> None:
    with MjpegServer(port=PORT + 3) as server:
        with pytest.raises(ValueError, match="RGB uint8"):
            server.publish(np.zeros((8, 8), np.uint8))
        with pytest.raises(ValueError, match="RGB uint8"):
            server.publish(np.zeros((8, 8, 3), np.float32))
        with pytest.raises(TypeError):
            server.publish(_image(1), truth={"x": object()})
        assert server.frames_published == 0


def test_close_ends_streams_and_frees_the_port() -> None:
    server = MjpegServer(port=PORT + 4)
    server.publish(_image(5))
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=3.0)
    sock.sendall(b"GET /stream.mjpg HTTP/1.0\r\n\r\n")
    sock.recv(4096)
    server.close()
    server.close()  # idempotent
    data = b""
    while chunk := sock.recv(65536):  # the server closed the stream: recv returns b""
        data += chunk
    sock.close()
    with MjpegServer(port=PORT + 4) as again:  # the port is free again
        assert again.port == PORT + 4


def test_two_hundred_viewers_connecting_at_once_all_get_frames() -> None:
    """The listen backlog admits a crowd: 200 viewers connecting in the same instant each get a frame
    (with a backlog of 5, 23 of 200 timed out connecting)."""
    import threading

    n = 200
    with MjpegServer(port=0) as server:
        server.publish(_image(90))
        start = threading.Barrier(n)
        got: list[bool] = [False] * n

        def viewer(i: int) -> None:
            start.wait()
            try:
                with socket.create_connection(("127.0.0.1", server.port), timeout=2.0) as sock:
                    sock.sendall(b"GET /stream.mjpg HTTP/1.0\r\n\r\n")
                    data = b""
                    while b"\xff\xd8" not in data:  # a JPEG's start
                        chunk = sock.recv(4096)
                        if not chunk:
                            return
                        data += chunk
                    got[i] = True
            except OSError:
                return

        threads = [threading.Thread(target=viewer, args=(i,)) for i in range(n)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=20.0)
        assert sum(got) == n


def _get_in_thread(url: str) -> tuple[threading.Thread, list]:
    answer: list = []
    thread = threading.Thread(target=lambda: answer.append(_get(url)))
    thread.start()
    return thread, answer


def test_on_demand_a_picture_or_a_truth_waits_for_the_publisher_s_answer() -> None:
    with MjpegServer(port=0, on_demand=True) as server:
        base = f"http://127.0.0.1:{server.port}"
        server.publish(_image(10), {"at": 0}, scene_s=1.0)
        assert server.asked() == (0, False) and not server.wait_asked(0.05)
        thread, answer = _get_in_thread(base + "/frame.jpg")  # on demand: a picture drawn for it
        assert server.wait_asked(2.0)
        number, new_frame = server.asked()
        assert number == 1 and new_frame and not answer  # nothing is sent before the answer
        server.answer(number)  # the truth of an unchanged scene answers no picture demand ...
        server.publish(_image(200), {"at": 1}, scene_s=2.0, answers=number)  # ... a new frame does
        thread.join(3.0)
        status, headers, _ = answer[0]
        assert status == 200 and headers["X-Frame-Number"] == "1"
        assert float(headers[SCENE_STAMP_HEADER]) == 2.0
        assert server.asked() == (0, False)

        thread, answer = _get_in_thread(base + "/truth.json")  # the truth of now: the scene stood still
        assert server.wait_asked(2.0) and server.asked() == (2, False)
        server.answer(2)
        thread.join(3.0)
        assert json.loads(answer[0][2]) == {"frame_number": 1, "truth": {"at": 1}}
        assert _get(base + "/truth.json?frame=0")[0] == 200  # a frame by number: no demand
        assert server.asked() == (0, False)


def test_without_demands_fresh_is_the_next_frame_published_and_truth_does_not_wait() -> None:
    with MjpegServer(port=0) as server:
        base = f"http://127.0.0.1:{server.port}"
        server.publish(_image(10), {"at": 0})
        assert _get(base + "/truth.json")[0] == 200 and server.asked() == (0, False)
        thread, answer = _get_in_thread(base + "/frame.jpg?fresh=1")
        time.sleep(0.2)
        assert not answer  # the latest frame (0) came before the request
        server.publish(_image(200), {"at": 1})
        thread.join(3.0)
        assert answer[0][1]["X-Frame-Number"] == "1"
        assert _get(base + "/frame.jpg")[1]["X-Frame-Number"] == "1"  # plain: the latest, at once
