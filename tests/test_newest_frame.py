"""The newest-frame slot that `StreamCamera` and `CameraTap` share: each frame at most once, the newest
one only, a reader's frame waited for, an ended source raised after its last frame, a closed one at once."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from perception.errors import CameraClosedError, CameraStreamEndedError, CameraTimeoutError
from perception.newest_frame import NewestFrame
from perception.types import Frame


def _frame(number: int) -> Frame:
    return Frame(np.zeros((2, 2, 3), np.uint8), time.monotonic(), number)


def test_the_newest_frame_once_and_a_timeout_with_the_reason() -> None:
    slot = NewestFrame("cam")
    slot.put(_frame(0))
    slot.put(_frame(1))  # the reader outran the consumer: frame 0 is skipped
    assert slot.take(0.1, lambda: "unused").frame_number == 1
    with pytest.raises(CameraTimeoutError, match="stalled here") as info:
        slot.take(0.05, lambda: "stalled here")  # frame 1 is not handed out twice
    assert info.value.timeout_s == 0.05


def test_a_frame_put_while_waiting_is_returned() -> None:
    slot = NewestFrame("cam")
    threading.Timer(0.05, slot.put, args=(_frame(3),)).start()
    start = time.monotonic()
    assert slot.take(2.0, lambda: "none").frame_number == 3
    assert time.monotonic() - start < 1.0


def test_an_end_comes_after_the_last_frame_and_a_close_at_once() -> None:
    slot = NewestFrame("cam")
    slot.put(_frame(0))
    slot.end(CameraStreamEndedError("cam", "end of file after 1 frames"))
    assert slot.take(0.1, lambda: "none").frame_number == 0  # the last frame first
    with pytest.raises(CameraStreamEndedError, match="end of file"):
        slot.take(0.1, lambda: "none")
    assert isinstance(slot.ended, CameraStreamEndedError)
    assert slot.close() is True and slot.close() is False
    slot.put(_frame(1))
    with pytest.raises(CameraClosedError):
        slot.take(0.1, lambda: "none")
