"""The simulated MAVLink vehicle's truth names every target, so a sim-mavlink (or PX4) mission can be
judged for wrong-target centrings as the in-process sim is."""

from __future__ import annotations

import numpy as np

from controller.missions.kits.simulated import SimTruth
from controller.missions.truth import TrueTarget
from sim_world.rendering.camera import CameraConfig
from sim_world.rendering.mjpeg import MjpegServer
from sim_world.rendering.video import frame_truth
from sim_world.scene.config import DEFAULT_SCENE, with_targets
from sim_world.world import World, WorldConfig


def test_frame_truth_lists_every_target_named_first_with_its_kind_colour_and_offset() -> None:
    scene = with_targets(DEFAULT_SCENE, count=(3, 3))
    with World(WorldConfig(scene=scene, camera=CameraConfig(width=96, height=96)), seed=11) as world:
        world.teleport((0.0, 0.5, 1.5), np.pi / 2)  # in front of the wall, facing it (north)
        render = world.render()
        s = world.state()
        pose = [*s.position_enu_m, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, world.time_s]
        truth = frame_truth(world, render, pose, np.zeros(3))
        expected = world.targets_truth(render)
        kinds = [(t.kind, t.attribute) for t in world.scene.targets]
    assert len(truth["targets"]) == 3
    assert [(t["kind"], t["attribute"]) for t in truth["targets"]] == kinds
    for served, true in zip(truth["targets"], expected, strict=True):
        assert served["in_view"] == bool(true.in_view)
        np.testing.assert_allclose(served["offset_px"], true.offset_px, atol=1e-3)
    # The named target's entry is the one the `target` block (success judging) describes.
    assert truth["targets"][0]["offset_px"] == truth["target"]["offset_px"]
    assert truth["targets"][0]["kind"] == truth["target"]["kind"]


def test_sim_truth_reads_every_target_over_http_and_tells_when_it_cannot() -> None:
    image = np.zeros((8, 8, 3), np.uint8)
    with MjpegServer(port=18710) as server:
        probe = SimTruth(f"http://127.0.0.1:{server.port}/truth.json")
        assert probe.targets() is None  # nothing published yet (503): no truth, no guess
        server.publish(
            image,
            truth={
                "target": {"offset_px": [3.0, -4.0], "in_view": True},
                "targets": [
                    {"kind": "gauge", "offset_px": [3.0, -4.0], "in_view": True},
                    {"kind": "valve", "offset_px": [500.0, 2.0], "in_view": False},
                    {"kind": "switchbox", "offset_px": [-60.5, 7.25], "in_view": True},
                ],
            },
        )
        assert probe.targets() == [
            TrueTarget("gauge", None, (3.0, -4.0)),
            TrueTarget("valve", None, None),
            TrueTarget("switchbox", None, (-60.5, 7.25)),
        ]
        assert probe.offset_px() == (3.0, -4.0)
        server.publish(image, truth={"target": {"offset_px": [1.0, 1.0], "in_view": True}})
        assert probe.targets() is None  # an older simulator: the named target only
