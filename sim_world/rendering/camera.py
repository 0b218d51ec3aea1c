"""The drone's forward camera: an explicit pinhole model rendered with PyBullet.

The intrinsics are the single source of truth: `fx = (W/2) / tan(hfov/2)`,
`fy = fx` (square pixels), `(cx, cy) = (W/2, H/2)`. PyBullet's projection matrix
is derived from them (vertical FOV `2·atan((H/2)/fy)`, aspect `W/H`), and the
view matrix is built from the full camera rotation, so `project()` and the
rendered image agree to a fraction of a pixel for any resolution, aspect ratio
and attitude (unlike gym-pybullet-drones, whose camera ignores roll and assumes a
square aspect).

Camera frame (OpenCV style): x right, y down, z forward (the optical axis).
Image: u right, v down, origin at the top-left corner of the top-left pixel, so
pixel i covers [i, i+1) and its centre is i + 0.5.

Mounts:
- ``gimbal`` (default; as inspection drones carry): the camera stays level (no
  roll or pitch) and follows the body's yaw.
- ``body``: rigidly attached; follows roll, pitch and yaw.
In both cases the camera *position* is the body centre plus the FLU offset
rotated by the full body attitude (the gimbal hangs from the airframe).
"""

from __future__ import annotations

import functools
import math
import statistics
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np
import pybullet as p

Mount = Literal["gimbal", "body"]

# Columns: the camera axes (right, down, forward) expressed in body FLU.
_R_BODY_FROM_CAM = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


class BodyPose(Protocol):
    """What the camera needs from a rigid-body state (`quadrotor.RigidBodyState` fits)."""

    @property
    def position_enu_m(self) -> np.ndarray: ...

    @property
    def quaternion_xyzw(self) -> np.ndarray: ...


@dataclass(frozen=True)
class CameraConfig:
    """Resolution, field of view, mount and clipping planes of the forward camera.

    The default offset puts the lens 12 cm ahead of and 4 cm below the body centre,
    where a small gimbal hangs: far enough below the propeller discs that they stay
    out of a 60° view.
    """

    width: int = 224
    height: int = 224
    hfov_deg: float = 60.0
    mount: Mount = "gimbal"
    offset_flu_m: tuple[float, float, float] = (0.12, 0.0, -0.04)
    near_m: float = 0.05
    far_m: float = 30.0

    def __post_init__(self) -> None:
        if self.width < 8 or self.height < 8:
            raise ValueError(f"camera resolution must be at least 8x8, got {self.width}x{self.height}")
        if not 1.0 <= self.hfov_deg <= 170.0:
            raise ValueError(f"hfov_deg must be in [1, 170], got {self.hfov_deg}")
        if self.mount not in ("gimbal", "body"):
            raise ValueError(f"mount must be 'gimbal' or 'body', got {self.mount!r}")
        if not 0.0 < self.near_m < self.far_m:
            raise ValueError(f"need 0 < near_m < far_m, got near_m={self.near_m}, far_m={self.far_m}")
        if len(self.offset_flu_m) != 3:
            raise ValueError(f"offset_flu_m must have 3 components, got {self.offset_flu_m!r}")


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels (principal point at the image centre)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    @classmethod
    def from_config(cls, config: CameraConfig) -> Intrinsics:
        fx = (config.width / 2.0) / math.tan(math.radians(config.hfov_deg) / 2.0)
        return cls(
            fx=fx,
            fy=fx,
            cx=config.width / 2.0,
            cy=config.height / 2.0,
            width=config.width,
            height=config.height,
        )

    @property
    def vfov_deg(self) -> float:
        """The vertical field of view implied by fy and the height."""
        return math.degrees(2.0 * math.atan((self.height / 2.0) / self.fy))

    def as_dict(self) -> dict[str, float]:
        return {"fx": self.fx, "fy": self.fy, "cx": self.cx, "cy": self.cy}


@dataclass(frozen=True)
class Lighting:
    """TinyRenderer lighting, passed to `p.getCameraImage` as keyword arguments."""

    direction: tuple[float, float, float] = (0.4, -1.0, 2.0)
    colour: tuple[float, float, float] = (1.0, 1.0, 1.0)
    distance_m: float = 10.0
    ambient: float = 0.6
    diffuse: float = 0.5
    specular: float = 0.05
    shadow: bool = False

    def kwargs(self) -> dict[str, object]:
        return {
            "lightDirection": list(self.direction),
            "lightColor": list(self.colour),
            "lightDistance": self.distance_m,
            "lightAmbientCoeff": self.ambient,
            "lightDiffuseCoeff": self.diffuse,
            "lightSpecularCoeff": self.specular,
            "shadow": int(self.shadow),
        }


@dataclass(frozen=True)
class Render:
    """One camera frame. `seg` holds PyBullet unique body ids (−1 = background), or None
    when the frame was rendered without a segmentation mask."""

    rgb: np.ndarray  # (H, W, 3) uint8
    depth_m: np.ndarray  # (H, W) float32, distance along the optical axis
    seg: np.ndarray | None  # (H, W) int32


@functools.cache
def _gaussian_quantiles() -> np.ndarray:
    """The standard normal at the 65,536 mid-quantiles: indexing it with uniform uint16 draws
    samples the normal (by inverse transform) about twice as fast as `standard_normal`."""
    inv_cdf = statistics.NormalDist().inv_cdf
    n = 1 << 16
    return np.array([inv_cdf((k + 0.5) / n) for k in range(n)], dtype=np.float32)


def add_gaussian_noise(rgb: np.ndarray, std: float, rng: np.random.Generator) -> np.ndarray:
    """`rgb` (uint8) plus Gaussian noise of `std` grey levels, rounded and clipped to uint8."""
    levels = np.rint(_gaussian_quantiles() * np.float32(std)).astype(np.int16)
    out = rgb.astype(np.int16)
    out += levels[rng.integers(0, 1 << 16, size=rgb.shape, dtype=np.uint16)]
    np.clip(out, 0, 255, out=out)
    return out.astype(np.uint8)


def yaw_rotation(yaw_rad: float) -> np.ndarray:
    """Rotation about world z (ENU) by yaw."""
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class ForwardCamera:
    """A pinhole camera on the drone: pose from the body state, projection, rendering."""

    def __init__(self, config: CameraConfig | None = None) -> None:
        self.config = config or CameraConfig()
        self.intrinsics = Intrinsics.from_config(self.config)
        projection = list(
            p.computeProjectionMatrixFOV(
                fov=self.intrinsics.vfov_deg,
                aspect=self.config.width / self.config.height,
                nearVal=self.config.near_m,
                farVal=self.config.far_m,
            )
        )
        # TinyRenderer samples each pixel at its corner, not its centre, and flips rows;
        # shifting NDC by half a pixel (column 2 of the column-major matrix) makes pixel
        # (i, j) sample the ray through (i + 0.5, j + 0.5), the convention of project().
        projection[8] += 1.0 / self.config.width
        projection[9] += 1.0 / self.config.height
        self._projection = projection
        self._offset_flu = np.asarray(self.config.offset_flu_m, dtype=float)

    def pose(self, state: BodyPose) -> tuple[np.ndarray, np.ndarray]:
        """(camera position ENU, R_world_from_cam) with camera axes x right, y down, z forward."""
        r_body = np.asarray(p.getMatrixFromQuaternion(state.quaternion_xyzw), dtype=float).reshape(3, 3)
        position = np.asarray(state.position_enu_m, dtype=float) + r_body @ self._offset_flu
        if self.config.mount == "gimbal":
            forward = r_body[:, 0]
            r_mount = yaw_rotation(math.atan2(forward[1], forward[0]))
        else:
            r_mount = r_body
        return position, r_mount @ _R_BODY_FROM_CAM

    def project(self, points_enu: np.ndarray, state: BodyPose) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) of world points and their depth along the optical axis (N,).

        Points behind the camera get depth ≤ 0 and NaN pixel coordinates.
        """
        pts = np.atleast_2d(np.asarray(points_enu, dtype=float))
        position, r_world_from_cam = self.pose(state)
        cam = (pts - position) @ r_world_from_cam  # rows: R^T (p − c)
        z = cam[:, 2]
        k = self.intrinsics
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(z > 1e-9, k.fx * cam[:, 0] / z + k.cx, np.nan)
            v = np.where(z > 1e-9, k.fy * cam[:, 1] / z + k.cy, np.nan)
        return np.stack([u, v], axis=1), z

    def view_matrix(self, state: BodyPose) -> list[float]:
        """The OpenGL view matrix (column-major, 16 floats) of the camera at this state."""
        position, r = self.pose(state)
        # OpenGL camera axes in world: x right, y up, z backward.
        gl = np.stack([r[:, 0], -r[:, 1], -r[:, 2]])  # rows
        view = np.eye(4)
        view[:3, :3] = gl
        view[:3, 3] = -gl @ position
        return view.T.reshape(-1).tolist()

    def render(
        self,
        client_id: int,
        state: BodyPose,
        lighting: Lighting | None = None,
        noise_std: float = 0.0,
        rng: np.random.Generator | None = None,
        with_seg: bool = True,
    ) -> Render:
        """Render RGB, depth (metres) and optionally the segmentation mask with TinyRenderer.

        `noise_std` is the standard deviation of additive Gaussian pixel noise in
        8-bit intensity levels; it needs `rng` so that noise is reproducible.
        """
        cfg = self.config
        flags = 0 if with_seg else p.ER_NO_SEGMENTATION_MASK
        light = (lighting or Lighting()).kwargs()
        _, _, rgba, zbuf, seg = p.getCameraImage(
            cfg.width,
            cfg.height,
            viewMatrix=self.view_matrix(state),
            projectionMatrix=self._projection,
            renderer=p.ER_TINY_RENDERER,
            flags=flags,
            physicsClientId=client_id,
            **light,
        )
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(cfg.height, cfg.width, 4)[:, :, :3]
        if noise_std > 0.0:
            if rng is None:
                raise ValueError("camera noise needs a seeded rng (rng=None given with noise_std > 0)")
            rgb = add_gaussian_noise(rgb, noise_std, rng)
        else:
            rgb = np.ascontiguousarray(rgb)
        depth = self._linear_depth(np.asarray(zbuf, dtype=np.float32).reshape(cfg.height, cfg.width))
        seg_ids = np.asarray(seg, dtype=np.int32).reshape(cfg.height, cfg.width) if with_seg else None
        return Render(rgb=rgb, depth_m=depth, seg=seg_ids)

    def _linear_depth(self, zbuf: np.ndarray) -> np.ndarray:
        """Metric depth along the optical axis from the [0, 1] OpenGL depth buffer."""
        near, far = np.float32(self.config.near_m), np.float32(self.config.far_m)
        return far * near / (far - (far - near) * zbuf)
