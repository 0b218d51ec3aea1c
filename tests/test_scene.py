"""The inspection scene: reproducible from its seed, each target kind where it should be,
pose_for_offset geometry, clutter and distractors clear of the target, textures upright."""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pybullet as p
import pytest

from drone_inspect_core.frames import yaw_enu_to_ned_rad
from sim_world.scene.assets import AssetCache
from sim_world.scene.bodies import BodyBuilder, Part
from sim_world.scene.builder import Scene
from sim_world.scene.config import DEFAULT_SCENE, SceneConfig
from sim_world.scene.sampling import (
    GAUGE_STANDOFF_M,
    SWITCHBOX_DEPTH_M,
    VALVE_STANDOFF_M,
    rects_overlap,
    sample_scene,
    target_footprint,
)

STANDOFF = {"gauge": GAUGE_STANDOFF_M, "valve": VALVE_STANDOFF_M, "switchbox": SWITCHBOX_DEPTH_M}


def only(kind: str, **clutter: object) -> SceneConfig:
    target = DEFAULT_SCENE.target.model_copy(update={"kinds": (kind,)})
    return DEFAULT_SCENE.model_copy(
        update={"target": target, "clutter": DEFAULT_SCENE.clutter.model_copy(update=clutter)}
    )


@pytest.fixture
def client() -> Iterator[int]:
    cid = p.connect(p.DIRECT)
    yield cid
    p.disconnect(cid)


@pytest.fixture(scope="module")
def asset_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("assets")


def render(
    cid: int, position: np.ndarray, yaw_enu_rad: float, size: int, lighting: dict | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """RGB and segmentation from a level pinhole camera (hfov 60°) at a pose."""
    forward = np.array([math.cos(yaw_enu_rad), math.sin(yaw_enu_rad), 0.0])
    view = p.computeViewMatrix(position.tolist(), (position + forward).tolist(), [0, 0, 1])
    proj = p.computeProjectionMatrixFOV(60.0, 1.0, 0.05, 50.0)
    _, _, rgba, _, seg = p.getCameraImage(
        size, size, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=cid, **(lighting or {})
    )
    return np.asarray(rgba, np.uint8).reshape(size, size, 4)[:, :, :3], np.asarray(seg).reshape(size, size)


def test_same_seed_same_scene_and_texture_bytes(tmp_path: Path) -> None:
    scenes, files = [], []
    for run in range(2):  # separate asset folders: the textures are drawn afresh each time
        cid = p.connect(p.DIRECT)
        try:
            scenes.append(Scene.build(cid, DEFAULT_SCENE, 11, asset_dir=tmp_path / f"run{run}").params())
        finally:
            p.disconnect(cid)
        files.append({f.name: f.read_bytes() for f in sorted((tmp_path / f"run{run}").glob("*.png"))})
    assert scenes[0] == scenes[1]
    assert files[0] and files[0] == files[1]

    cid = p.connect(p.DIRECT)
    try:
        other = Scene.build(cid, DEFAULT_SCENE, 12, asset_dir=tmp_path / "run2").params()
    finally:
        p.disconnect(cid)
    assert other != scenes[0]
    assert other["target"] != scenes[0]["target"]
    assert {f.name for f in (tmp_path / "run2").glob("*.png")} != set(files[0])


def test_streams_are_independent() -> None:
    """More distractors must not move the target or change the light (per-concern streams)."""
    few = sample_scene(only("gauge", distractors=(0, 0)), 5)
    many = sample_scene(only("gauge", distractors=(4, 4)), 5)
    assert few.target == many.target and few.lighting == many.lighting
    assert len(few.distractors) == 0 and len(many.distractors) > 0


@pytest.mark.parametrize("kind", ["gauge", "valve", "switchbox"])
def test_each_kind_builds_where_sampled(client: int, asset_dir: Path, kind: str) -> None:
    scene = Scene.build(client, only(kind), 3, asset_dir=asset_dir)
    t = scene.sampled.target
    assert scene.target_kind == kind == t.kind
    north = DEFAULT_SCENE.wall.north_m
    assert scene.wall_north_m == north
    centre = scene.target_centre_enu_m
    np.testing.assert_allclose(centre, [t.east_m, north - STANDOFF[kind], t.height_m], atol=0.002)
    assert DEFAULT_SCENE.target.east_m[0] <= centre[0] <= DEFAULT_SCENE.target.east_m[1]
    base, _ = p.getBasePositionAndOrientation(scene.target_body_id, physicsClientId=client)
    np.testing.assert_allclose(base, centre, atol=1e-6)

    outline = scene.target_corners_enu_m
    assert 16 <= len(outline) <= 32
    np.testing.assert_allclose(outline[:, 1], centre[1])  # all on the front face
    half = np.abs(outline - centre).max(axis=0)
    assert half[0] == pytest.approx(scene.target_size_m / 2, rel=1e-6)
    assert half[2] == pytest.approx(t.face_height_m / 2, rel=1e-6)

    # Seen from 2 m straight in front, the target's pixels centre on the image centre
    # and the projected outline bounds them.
    size = 96
    position, yaw = scene.pose_for_offset(0.0, 0.0, 2.0, 0.0)
    _, seg = render(client, position, yaw, size, scene.lighting.kwargs())
    vs, us = np.nonzero(seg == scene.target_body_id)
    assert len(us) > 20
    assert (us.mean() + 0.5 - size / 2, vs.mean() + 0.5 - size / 2) == pytest.approx((0.0, 0.0), abs=1.5)
    focal = (size / 2) / math.tan(math.radians(30.0))
    half_width_px = focal * (scene.target_size_m / 2) / 2.0
    assert (us.max() + 1 - us.min()) / 2 == pytest.approx(half_width_px, abs=1.5)


def test_params_are_json_and_match_the_scene(client: int, asset_dir: Path) -> None:
    scene = Scene.build(client, DEFAULT_SCENE, 21, asset_dir=asset_dir)
    params = json.loads(json.dumps(scene.params()))
    assert params["seed"] == 21
    assert params["target"]["kind"] == scene.target_kind
    assert params["camera_noise_std"] == pytest.approx(scene.camera_noise_std, abs=1e-4)
    lo, hi = DEFAULT_SCENE.camera_noise_std
    assert lo <= scene.camera_noise_std <= hi
    assert len(params["distractors"]) == len(scene.distractor_body_ids)
    assert len(params["clutter"]) == len(scene.clutter_body_ids)


def test_lighting_follows_the_config(client: int, asset_dir: Path) -> None:
    light = DEFAULT_SCENE.lighting.model_copy(
        update={"azimuth_deg": (180.0, 180.0), "elevation_deg": (30.0, 30.0), "shadow": True}
    )
    config = DEFAULT_SCENE.model_copy(update={"lighting": light})
    kwargs = Scene.build(client, config, 4, asset_dir=asset_dir).lighting.kwargs()
    # From the south (behind a drone facing the wall), 30° up.
    np.testing.assert_allclose(kwargs["lightDirection"], [0.0, -math.cos(math.radians(30)), 0.5], atol=1e-9)
    assert kwargs["shadow"] == 1
    assert (
        DEFAULT_SCENE.lighting.ambient[0] <= kwargs["lightAmbientCoeff"] <= DEFAULT_SCENE.lighting.ambient[1]
    )


def test_pose_for_offset_geometry(client: int, asset_dir: Path) -> None:
    scene = Scene.build(client, only("valve"), 8, asset_dir=asset_dir)
    centre = scene.target_centre_enu_m
    position, yaw = scene.pose_for_offset(0.0, 0.0, 2.0, 0.0)
    np.testing.assert_allclose(position - centre, [0.0, -2.0, 0.0])
    assert yaw == pytest.approx(math.pi / 2)  # facing north, the wall

    position, yaw = scene.pose_for_offset(0.4, -0.3, 1.5, 10.0)
    np.testing.assert_allclose(position - centre, [0.4, -1.5, -0.3], atol=1e-12)
    assert scene.wall_north_m - position[1] == pytest.approx(1.5 + VALVE_STANDOFF_M)
    assert yaw == pytest.approx(math.radians(80.0))  # 10° clockwise: towards east
    assert yaw_enu_to_ned_rad(yaw) == pytest.approx(math.radians(10.0))

    _, yaw = scene.pose_for_offset(0.0, 0.0, 2.0, -200.0)
    assert -math.pi <= yaw < math.pi
    assert math.cos(yaw) == pytest.approx(math.cos(math.radians(290.0)))


def test_turning_right_moves_the_target_left_in_the_image(client: int, asset_dir: Path) -> None:
    scene = Scene.build(client, only("switchbox", distractors=(0, 0)), 2, asset_dir=asset_dir)
    columns = []
    for yaw_deg in (0.0, 8.0):
        position, yaw = scene.pose_for_offset(0.0, 0.0, 2.0, yaw_deg)
        _, seg = render(client, position, yaw, 64)
        columns.append(np.nonzero(seg == scene.target_body_id)[1].mean())
    assert columns[1] < columns[0] - 5


def test_clutter_and_distractors_never_overlap_the_target(client: int, asset_dir: Path) -> None:
    """Built bodies, checked in the wall plane with PyBullet's own bounding boxes."""
    config = DEFAULT_SCENE.model_copy(
        update={
            "clutter": DEFAULT_SCENE.clutter.model_copy(update={"density": (1.0, 1.0), "distractors": (4, 4)})
        }
    )
    keep = config.clutter.keep_out_m
    placed = 0
    for seed in range(12):
        p.resetSimulation(physicsClientId=client)
        scene = Scene.build(client, config, seed, asset_dir=asset_dir)
        lo, hi = p.getAABB(scene.target_body_id, physicsClientId=client)
        target = (lo[0] - keep, lo[2] - keep, hi[0] + keep, hi[2] + keep)
        for body in (*scene.distractor_body_ids, *scene.clutter_body_ids):
            blo, bhi = p.getAABB(body, physicsClientId=client)
            # PyBullet pads AABBs by a few mm; shrink back before comparing.
            rect = (blo[0] + 0.005, blo[2] + 0.005, bhi[0] - 0.005, bhi[2] - 0.005)
            assert not rects_overlap(rect, target), f"seed {seed}: body {body} overlaps the target"
        placed += len(scene.distractor_body_ids)
    assert placed >= 12  # the test saw distractors (most scenes have room for several)


def test_sampled_footprints_keep_out_of_the_target_many_seeds() -> None:
    config = DEFAULT_SCENE.model_copy(
        update={
            "clutter": DEFAULT_SCENE.clutter.model_copy(update={"density": (1.0, 1.0), "distractors": (4, 4)})
        }
    )
    keep = config.clutter.keep_out_m
    for seed in range(300):
        params = sample_scene(config, seed)
        x0, z0, x1, z1 = target_footprint(params.target)
        keep_out = (x0 - keep, z0 - keep, x1 + keep, z1 + keep)
        items = (*params.distractors, *params.clutter)
        assert not any(rects_overlap(item.footprint(), keep_out) for item in items), seed
        compact = [i for i in items if not i.kind.startswith(("pipe", "conduit"))]
        for a in range(len(compact)):
            for b in range(a + 1, len(compact)):
                assert not rects_overlap(compact[a].footprint(), compact[b].footprint()), seed


@pytest.mark.parametrize("mesh", ["quad", "disc"])
def test_textures_appear_upright_and_unmirrored(client: int, tmp_path: Path, mesh: str) -> None:
    """A texture red in its top-left quarter shows red top-left on a front face seen from the south."""
    image = np.zeros((64, 64, 3), np.uint8)
    image[:, :] = (0, 200, 0)
    image[:32, :32] = (220, 0, 0)
    assets = AssetCache(tmp_path)
    texture = assets.png(("probe",), lambda: image)
    mesh_file = assets.quad("front") if mesh == "quad" else assets.disc()
    BodyBuilder(client).body(
        [Part("mesh", (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), mesh=mesh_file, texture=texture)], (0.0, 0.0, 0.0)
    )
    rgb, _ = render(
        client,
        np.array([0.0, -1.2, 0.0]),
        math.pi / 2,
        64,
        {"lightAmbientCoeff": 1.0, "lightDiffuseCoeff": 0.0},
    )
    top_left, bottom_right = rgb[24, 24].astype(int), rgb[40, 40].astype(int)
    assert top_left[0] > 150 and top_left[1] < 60
    assert bottom_right[1] > 150 and bottom_right[0] < 60
    top_right = rgb[24, 40].astype(int)
    assert top_right[1] > 150 and top_right[0] < 60


def test_gauge_dial_is_drawn_on_the_face(client: int, asset_dir: Path) -> None:
    """Close up, the dial is light with dark ticks and a needle: many dark and light pixels."""
    scene = Scene.build(client, only("gauge"), 30, asset_dir=asset_dir)
    position, yaw = scene.pose_for_offset(0.0, 0.0, 0.5, 0.0)
    rgb, seg = render(client, position, yaw, 128, {"lightAmbientCoeff": 0.9, "lightDiffuseCoeff": 0.1})
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    face = grey[seg == scene.target_body_id]
    assert np.mean(face > 180) > 0.3
    assert np.mean(face < 80) > 0.02


def test_remove_takes_every_body_out(client: int, asset_dir: Path) -> None:
    scene = Scene.build(client, DEFAULT_SCENE, 6, asset_dir=asset_dir)
    assert p.getNumBodies(physicsClientId=client) == len(scene.body_ids())
    scene.remove()
    assert p.getNumBodies(physicsClientId=client) == 0
