"""The floor the camera sees is the floor's textured visual, never its collision plane.

A body without a visual shape is drawn from its collision shapes; the floor's infinite
collision plane, drawn that way, is a 256 m checkerboard coplanar with the floor's
visual, so the two z-fought (which one showed changed from pose to pose) and the plane
cost ~20% of a 224 px frame. `BodyBuilder.plane_collider` makes it transparent.
"""

from __future__ import annotations

import numpy as np
import pybullet as p

from sim_world.world import World


def test_floor_collision_plane_is_never_rendered() -> None:
    with World(seed=0) as world:
        # High and tilted enough to see a large stretch of floor in front of the wall (the
        # old renderer showed the checkerboard plane on ~16,000 of these pixels).
        position, yaw = world.scene.pose_for_offset(-0.6, -0.4, 3.3, 14.0)
        world.teleport(position, yaw)
        (collider,) = world.scene.other_body_ids
        assert p.getVisualShapeData(collider, physicsClientId=world.client_id)[0][7][3] == 0.0
        seg = world.render(with_seg=True).seg
        assert seg is not None
        assert not np.any(seg == collider)
        assert np.count_nonzero(seg == world.scene.floor_body_id) > 5000
