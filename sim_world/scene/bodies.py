"""Static PyBullet bodies made of simple parts (boxes, cylinders, textured faces).

A body with several parts is one multibody (a base plus fixed, massless links), so the
segmentation mask shows the whole object under one body id: the target's mask is the
target, bezel and face together. Parts are placed by their visual frame relative to
the body origin, in world-aligned axes. Collision is one box per body (what a drone
would hit), or none for thin decorations.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import pybullet as p

from sim_world.scene.config import hex_to_rgb

Quaternion = tuple[float, float, float, float]
Vec3 = tuple[float, float, float]

_S = math.sqrt(0.5)
ALONG_X: Quaternion = (0.0, _S, 0.0, _S)
"""Orientation that lays a cylinder (PyBullet: along local z) along world x (east)."""
ALONG_Y: Quaternion = (_S, 0.0, 0.0, _S)
"""... along world y (out of the wall)."""
ALONG_Z: Quaternion = (0.0, 0.0, 0.0, 1.0)


def along_xz(angle_rad: float) -> Quaternion:
    """Orientation of a cylinder along the direction (cos a, 0, sin a) in the wall plane."""
    theta = math.pi / 2 - angle_rad  # rotation about y taking z to (sin θ, 0, cos θ)
    return 0.0, math.sin(theta / 2), 0.0, math.cos(theta / 2)


def rgba(colour: str, alpha: float = 1.0) -> tuple[float, float, float, float]:
    """`'#rrggbb'` to PyBullet's RGBA floats."""
    r, g, b = hex_to_rgb(colour)
    return r / 255.0, g / 255.0, b / 255.0, alpha


def shaded(colour: str, factor: float) -> str:
    """The colour darkened (factor < 1) or lightened, as `'#rrggbb'`."""
    return "#" + "".join(f"{min(255, round(c * factor)):02x}" for c in hex_to_rgb(colour))


@dataclass(frozen=True)
class Part:
    """One visual piece of a body.

    `shape` "box" (size = half extents), "cylinder" (size = (radius, length), along local
    z before `orientation`) or "mesh" (size = mesh scale, `mesh` = OBJ file). A `texture`
    PNG is shown with the colour multiplied in, so textured parts stay white.
    """

    shape: str
    size: tuple[float, ...]
    position: Vec3
    colour: str = "#ffffff"
    orientation: Quaternion = ALONG_Z
    mesh: Path | None = None
    texture: Path | None = None


class BodyBuilder:
    """Creates static bodies in one client, loading each texture file once."""

    def __init__(self, client_id: int) -> None:
        self.client_id = client_id
        self._textures: dict[Path, int] = {}

    def texture_id(self, path: Path) -> int:
        if path not in self._textures:
            tex = p.loadTexture(str(path), physicsClientId=self.client_id)
            if tex < 0:
                raise RuntimeError(f"PyBullet could not load the texture {path}")
            self._textures[path] = tex
        return self._textures[path]

    def _visual(self, part: Part) -> int:
        common = {
            "rgbaColor": rgba(part.colour),
            "visualFramePosition": part.position,
            "visualFrameOrientation": part.orientation,
            "physicsClientId": self.client_id,
        }
        if part.shape == "box":
            return p.createVisualShape(p.GEOM_BOX, halfExtents=part.size, **common)
        if part.shape == "cylinder":
            return p.createVisualShape(p.GEOM_CYLINDER, radius=part.size[0], length=part.size[1], **common)
        if part.shape == "mesh" and part.mesh is not None:
            return p.createVisualShape(p.GEOM_MESH, fileName=str(part.mesh), meshScale=part.size, **common)
        raise ValueError(f"unknown part shape {part.shape!r} (or a mesh part without a file)")

    def body(
        self,
        parts: list[Part],
        position: Vec3,
        collision_half_extents: Vec3 | None = None,
        collision_offset: Vec3 = (0.0, 0.0, 0.0),
    ) -> int:
        """A static body at `position` made of `parts`; returns its unique id."""
        cid = self.client_id
        collision = -1
        if collision_half_extents is not None:
            collision = p.createCollisionShape(
                p.GEOM_BOX,
                halfExtents=collision_half_extents,
                collisionFramePosition=collision_offset,
                physicsClientId=cid,
            )
        visuals = [self._visual(part) for part in parts]
        links = len(parts) - 1
        body = p.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=collision,
            baseVisualShapeIndex=visuals[0],
            basePosition=position,
            linkMasses=[0.0] * links,
            linkCollisionShapeIndices=[-1] * links,
            linkVisualShapeIndices=visuals[1:],
            linkPositions=[(0.0, 0.0, 0.0)] * links,
            linkOrientations=[ALONG_Z] * links,
            linkInertialFramePositions=[(0.0, 0.0, 0.0)] * links,
            linkInertialFrameOrientations=[ALONG_Z] * links,
            linkParentIndices=[0] * links,
            linkJointTypes=[p.JOINT_FIXED] * links,
            linkJointAxis=[(0.0, 0.0, 1.0)] * links,
            physicsClientId=cid,
        )
        for link, part in enumerate(parts, start=-1):
            if part.texture is not None:
                p.changeVisualShape(
                    body, link, textureUniqueId=self.texture_id(part.texture), physicsClientId=cid
                )
        return body

    def plane_collider(self) -> int:
        """An infinite collision plane at z = 0 (the floor the drone stands on), not rendered.

        PyBullet draws the collision shapes of a body without a visual shape: TinyRenderer
        would draw this plane as a 256 m checkerboard coplanar with the floor's visual (the
        two z-fight, so which one shows changes from pose to pose) at ~20% of a 224 px
        frame's cost. Fully transparent shapes are skipped by the renderer. The body gets a
        visual of its own (a transparent millimetre box): without one PyBullet builds that
        checkerboard's texture (megabytes, byte by byte) every time a world is built, which
        was most of a warm reset's time in a bridge's world.
        """
        cid = self.client_id
        shape = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
        unseen = p.createVisualShape(
            p.GEOM_BOX, halfExtents=(0.001, 0.001, 0.001), rgbaColor=(1.0, 1.0, 1.0, 0.0), physicsClientId=cid
        )
        return p.createMultiBody(0.0, shape, unseen, (0.0, 0.0, 0.0), physicsClientId=cid)
