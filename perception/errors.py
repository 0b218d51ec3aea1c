"""Typed errors of the perception package.

Every error names what failed (the camera source, the checkpoint file, the dataset
file and line) so that a user can act on the message without a traceback.
"""

from __future__ import annotations


class PerceptionError(Exception):
    """Base class of every error raised by `perception`."""


class CameraError(PerceptionError):
    """A camera could not deliver a frame. Catch this to handle every camera failure."""

    def __init__(self, source: str, message: str) -> None:
        super().__init__(f"camera {source}: {message}")
        self.source = source


class CameraOpenError(CameraError):
    """The source could not be opened (bad URL, refused connection, missing device or file)."""


class CameraTimeoutError(CameraError):
    """No new frame arrived within the timeout (a frozen or stalled stream)."""

    def __init__(self, source: str, timeout_s: float, message: str = "") -> None:
        detail = f": {message}" if message else ""
        super().__init__(source, f"no new frame within {timeout_s:.3g} s{detail}")
        self.timeout_s = timeout_s


class CameraStreamEndedError(CameraError):
    """The stream ended or dropped (server closed the connection, end of a video file)."""


class CameraFrozenError(CameraError):
    """New frames keep arriving with the very same picture, though the vehicle moved (a stuck encoder)."""


class CameraClosedError(CameraError):
    """`read()` was called on a camera after `close()`."""


class DetectorCheckpointError(PerceptionError):
    """A detector checkpoint is missing, corrupt or does not match its config."""

    def __init__(self, path: object, message: str) -> None:
        super().__init__(f"detector checkpoint {path}: {message}")
        self.path = path


class ColourCheckpointError(DetectorCheckpointError):
    """A trim-colour reader checkpoint (`perception.colour_model`) is missing, corrupt or does not match
    its config. A detector reads colours with it, so whatever handles a detector checkpoint's error
    handles this one."""

    def __init__(self, path: object, message: str) -> None:
        PerceptionError.__init__(self, f"colour reader checkpoint {path}: {message}")
        self.path = path
