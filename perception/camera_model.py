"""A camera's pinhole model, from a camera file, and where a point seen from one pose appears from another.

The camera file (YAML or JSON) gives the image size and either a field of view or a calibrated matrix:

```yaml
width: 640
height: 480
hfov_deg: 70.0                  # square pixels; vfov_deg too for non-square ones
# or a calibration (OpenCV's camera matrix, e.g. from cv2.calibrateCamera):
# matrix: [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
offset_frd_m: [0.12, 0.0, 0.04]  # the lens from the body centre, body FRD (optional, default 0)
```

Lens distortion is not modelled: calibrate and undistort upstream for a wide lens. The camera is
taken as level and turning with the vehicle's yaw (a gimbal, as inspection drones carry, and as the
simulated camera is): a pose is local NED + yaw. Offsets are from the image centre (W/2, H/2), u right,
v down (docs/architecture.md), so a principal point off the centre shows in them.

`offset_at(...)` is the pose geometry of a flown collection's labels: a target seen at `goal_offset_px`
from the goal pose, `depth_m` away along the optical axis, is a point in the local frame; from another
pose it projects to the offset returned.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import Field, model_validator

from drone_inspect_core.config_files import ConfigFileError, StrictModel, read_yaml, validate_mapping


class CameraFileError(ConfigFileError):
    """A camera file that cannot be used; the message names the file and the field."""


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics in pixels, the image size, and the lens's offset from the body centre (FRD, m)."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.width < 8 or self.height < 8:
            raise ValueError(
                f"CameraModel: the image must be at least 8x8 px, got {self.width}x{self.height}"
            )
        if not (self.fx > 0 and self.fy > 0 and math.isfinite(self.fx) and math.isfinite(self.fy)):
            raise ValueError(f"CameraModel: focal lengths must be > 0, got fx={self.fx}, fy={self.fy}")

    @classmethod
    def from_fov(
        cls,
        width: int,
        height: int,
        hfov_deg: float,
        vfov_deg: float | None = None,
        offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> CameraModel:
        """Square pixels unless `vfov_deg` is given; the principal point at the image centre."""
        fx = (width / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
        fy = fx if vfov_deg is None else (height / 2.0) / math.tan(math.radians(vfov_deg) / 2.0)
        return cls(width, height, fx, fy, width / 2.0, height / 2.0, offset_frd_m)

    @property
    def hfov_deg(self) -> float:
        return math.degrees(2.0 * math.atan((self.width / 2.0) / self.fx))

    def as_dict(self) -> dict[str, object]:
        return {
            "width": self.width, "height": self.height, "fx": self.fx, "fy": self.fy, "cx": self.cx,
            "cy": self.cy, "hfov_deg": round(self.hfov_deg, 4), "offset_frd_m": list(self.offset_frd_m),
        }  # fmt: skip

    # --- geometry --------------------------------------------------------------------------
    def lens_ned_m(self, pose: PoseNed) -> np.ndarray:
        """The lens position (NED) of a vehicle at `pose` (level camera turning with the yaw)."""
        forward, right, down = self.offset_frd_m
        f, r = _axes(pose.yaw_deg)
        return pose.position + forward * f + right * r + np.array([0.0, 0.0, down])

    def point_ned(self, pose: PoseNed, offset_px: tuple[float, float], depth_m: float) -> np.ndarray:
        """The local NED point seen at `offset_px` from `pose`, `depth_m` along the optical axis."""
        if not depth_m > 0.0:
            raise ValueError(f"depth_m must be > 0, got {depth_m}")
        x = (offset_px[0] + self.width / 2.0 - self.cx) / self.fx * depth_m  # right of the axis
        y = (offset_px[1] + self.height / 2.0 - self.cy) / self.fy * depth_m  # below the axis
        f, r = _axes(pose.yaw_deg)
        return self.lens_ned_m(pose) + depth_m * f + x * r + np.array([0.0, 0.0, y])

    def project_ned(self, pose: PoseNed, point_ned: np.ndarray) -> tuple[float, float, float]:
        """(du, dv, depth_m) of a local NED point seen from `pose`; depth ≤ 0: behind the camera."""
        f, r = _axes(pose.yaw_deg)
        rel = np.asarray(point_ned, dtype=float) - self.lens_ned_m(pose)
        z, x, y = float(rel @ f), float(rel @ r), float(rel[2])
        if z <= 1e-6:
            return math.nan, math.nan, z
        du = self.cx + self.fx * x / z - self.width / 2.0
        dv = self.cy + self.fy * y / z - self.height / 2.0
        return du, dv, z

    def pose_for_offset(
        self, point_ned: np.ndarray, offset_px: tuple[float, float], depth_m: float, yaw_deg: float
    ) -> PoseNed:
        """The vehicle pose (level camera, heading `yaw_deg`) that sees `point_ned` at `offset_px`,
        `depth_m` along the optical axis: `project_ned`'s inverse."""
        if not depth_m > 0.0:
            raise ValueError(f"depth_m must be > 0, got {depth_m}")
        x = (offset_px[0] + self.width / 2.0 - self.cx) / self.fx * depth_m
        y = (offset_px[1] + self.height / 2.0 - self.cy) / self.fy * depth_m
        f, r = _axes(yaw_deg)
        lens = np.asarray(point_ned, dtype=float) - depth_m * f - x * r - np.array([0.0, 0.0, y])
        forward, right, down = self.offset_frd_m
        body = lens - forward * f - right * r - np.array([0.0, 0.0, down])
        return PoseNed(float(body[0]), float(body[1]), float(body[2]), yaw_deg)

    def offset_at(
        self, goal: PoseNed, goal_offset_px: tuple[float, float], depth_m: float, pose: PoseNed
    ) -> tuple[float, float, float]:
        """Where a target seen at `goal_offset_px` from `goal` (`depth_m` away) appears from `pose`:
        (du, dv, its depth there)."""
        return self.project_ned(pose, self.point_ned(goal, goal_offset_px, depth_m))


@dataclass(frozen=True)
class PoseNed:
    """A vehicle pose as telemetry gives it: local NED position (m) and yaw (deg, from north, clockwise)."""

    north_m: float
    east_m: float
    down_m: float
    yaw_deg: float

    @property
    def position(self) -> np.ndarray:
        return np.array([self.north_m, self.east_m, self.down_m], dtype=float)

    def relative_to(self, origin: PoseNed) -> tuple[float, float, float]:
        """(forward, right, up) metres from `origin`, in `origin`'s heading frame."""
        f, r = _axes(origin.yaw_deg)
        delta = self.position - origin.position
        return float(delta @ f), float(delta @ r), float(-delta[2])

    def moved(self, forward_m: float, right_m: float, up_m: float, yaw_deg: float | None = None) -> PoseNed:
        """This pose moved (forward, right, up) in its own heading frame; optionally turned to `yaw_deg`."""
        f, r = _axes(self.yaw_deg)
        n, e, d = self.position + forward_m * f + right_m * r - np.array([0.0, 0.0, up_m])
        return PoseNed(float(n), float(e), float(d), self.yaw_deg if yaw_deg is None else yaw_deg)

    def as_dict(self) -> dict[str, float]:
        return {
            "north_m": self.north_m,
            "east_m": self.east_m,
            "down_m": self.down_m,
            "yaw_deg": self.yaw_deg,
        }


def _axes(yaw_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """The level camera's forward and right axes in NED at this yaw."""
    yaw = math.radians(yaw_deg)
    return np.array([math.cos(yaw), math.sin(yaw), 0.0]), np.array([-math.sin(yaw), math.cos(yaw), 0.0])


class _CameraFile(StrictModel):
    """The camera file's schema: the size, and a field of view or a calibrated matrix (or fx/fy/cx/cy)."""

    width: int = Field(ge=8, le=16384)
    height: int = Field(ge=8, le=16384)
    hfov_deg: float | None = Field(default=None, gt=1.0, lt=170.0)
    vfov_deg: float | None = Field(default=None, gt=1.0, lt=170.0)
    matrix: (
        tuple[tuple[float, float, float], tuple[float, float, float], tuple[float, float, float]] | None
    ) = None
    fx: float | None = Field(default=None, gt=0.0)
    fy: float | None = Field(default=None, gt=0.0)
    cx: float | None = None
    cy: float | None = None
    offset_frd_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @model_validator(mode="after")
    def _one_source_of_intrinsics(self) -> _CameraFile:
        given = [
            name
            for name, present in (
                ("hfov_deg", self.hfov_deg is not None),
                ("matrix", self.matrix is not None),
                ("fx", self.fx is not None),
            )
            if present
        ]
        if not given:
            raise ValueError(
                "intrinsics: none given; add hfov_deg (a field of view), matrix (a calibration) "
                "or fx/fy/cx/cy"
            )
        if len(given) > 1:
            raise ValueError(f"intrinsics: give one of hfov_deg, matrix or fx/fy/cx/cy, not {given}")
        if self.fx is not None and None in (self.fy, self.cx, self.cy):
            raise ValueError("intrinsics: fx needs fy, cx and cy beside it")
        if self.matrix is not None:
            (fx, skew, _), (zero, fy, _), last = self.matrix
            if fx <= 0 or fy <= 0 or skew != 0 or zero != 0 or tuple(last) != (0.0, 0.0, 1.0):
                raise ValueError("matrix: expected [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0")
        return self

    def model(self) -> CameraModel:
        if self.hfov_deg is not None:
            return CameraModel.from_fov(
                self.width, self.height, self.hfov_deg, self.vfov_deg, self.offset_frd_m
            )
        if self.matrix is not None:
            (fx, _, cx), (_, fy, cy), _ = self.matrix
        else:
            fx, fy, cx, cy = self.fx, self.fy, self.cx, self.cy  # type: ignore[assignment]
        return CameraModel(self.width, self.height, fx, fy, cx, cy, self.offset_frd_m)  # type: ignore[arg-type]


def load_camera_file(path: str | Path) -> CameraModel:
    """Read a camera file (YAML or JSON); `CameraFileError` names the file and the field at fault."""
    data = read_yaml(path, CameraFileError)  # JSON is YAML
    return validate_mapping(_CameraFile, data, path, CameraFileError).model()
