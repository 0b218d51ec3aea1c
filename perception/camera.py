"""The camera interface shared by the simulated and the streamed cameras."""

from __future__ import annotations

from abc import ABC, abstractmethod
from types import TracebackType

from perception.types import Frame


class Camera(ABC):
    """A source of RGB frames.

    `read()` returns a frame newer than the one it returned last, waiting at most
    `timeout_s` (the camera's own default when None) and raising
    `CameraTimeoutError` otherwise; every failure is a `CameraError`. `close()`
    releases the source and is safe to call twice. Use as a context manager.
    """

    @abstractmethod
    def read(self, timeout_s: float | None = None) -> Frame:
        """The newest frame not returned before."""

    @abstractmethod
    def close(self) -> None:
        """Release the source (idempotent)."""

    def __enter__(self) -> Camera:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
