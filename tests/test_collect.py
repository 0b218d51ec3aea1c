"""Data collection: a tiny dataset written by the real protocol, read back and checked row by row."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest

import sim_world.collection.collect as collect_module
from controller.planning.actions import Action, XMove, ZMove, label_from_offset
from drone_inspect_core.dataset import DatasetError
from drone_inspect_core.frames import ned_to_enu
from sim_world.collection.collect import CollectConfig, collect, load_manifest
from sim_world.collection.plan import SECTOR_DIRECTIONS, plan_collection
from sim_world.world import World, WorldConfig

TINY = {
    "seed": 5,
    "n_goal": 4,
    "n_per_sector": 2,
    "n_test": 9,
    "n_empty": 2,
    "size_px": 96,
    "images_per_scene": 8,
}


def _expected_action(sector: str) -> Action:
    if sector == "centre":
        return Action(XMove.NONE, ZMove.NONE)
    sx, sz = SECTOR_DIRECTIONS[sector]
    x = {1: XMove.RIGHT, 0: XMove.NONE, -1: XMove.LEFT}[sx]
    z = {1: ZMove.UP, 0: ZMove.NONE, -1: ZMove.DOWN}[sz]
    return Action(x, z)


@pytest.fixture(scope="module")
def tiny_dataset(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("collect") / "tiny"
    result = collect(CollectConfig(out_dir=out, workers=1, **TINY), progress=False)
    assert result.counts == {"goal": 4, "train": 16, "test": 9, "empty": 2}
    return out


def test_tiny_collection_rows_match_their_sectors_and_labels(tiny_dataset: Path) -> None:
    rows, meta = load_manifest(tiny_dataset)
    eps = meta["epsilon_px"]
    assert eps == pytest.approx(10 * 96 / 224)
    assert meta["complete"] is True and meta["counts"] == {"goal": 4, "train": 16, "test": 9, "empty": 2}
    assert meta["camera"]["fx"] == pytest.approx(48 / math.tan(math.radians(30)))
    assert len(rows) == 31 and len({r["id"] for r in rows}) == 31
    for row in rows:
        image = cv2.imread(str(tiny_dataset / row["image"]))
        assert image is not None and image.shape == (96, 96, 3)
        if row["split"] == "empty":
            assert row["bbox_px"] is None and not row["in_view"] and row["sector"] == "none"
            continue
        du, dv = row["offset_px"]
        assert (du, dv) == pytest.approx((row["centre_px"][0] - 48, row["centre_px"][1] - 48), abs=1e-2)
        assert label_from_offset(du, dv, eps) == _expected_action(row["sector"]), row["id"]
        assert row["in_view"] and row["bbox_px"] is not None and row["visible_fraction"] > 0.3
        assert meta["camera"]["width"] == 96 and 1.2 - 0.2 <= row["depth_m"] <= 3.5 + 0.2
        if row["split"] == "goal":
            assert math.hypot(du, dv) <= eps
    # Every training sector present, and the test split covers the centre and all eight sectors.
    assert {r["sector"] for r in rows if r["split"] == "train"} == set(SECTOR_DIRECTIONS)
    assert {r["sector"] for r in rows if r["split"] == "test"} == {*SECTOR_DIRECTIONS, "centre"}


def test_test_scenes_are_disjoint_from_training_scenes(tiny_dataset: Path) -> None:
    rows, meta = load_manifest(tiny_dataset)
    train_seeds, test_seeds = set(meta["train_scene_seeds"]), set(meta["test_scene_seeds"])
    assert train_seeds and test_seeds and not train_seeds & test_seeds
    for row in rows:
        expected = train_seeds if row["split"] in ("goal", "train") else test_seeds
        assert row["scene_seed"] in expected, row["id"]
    # The same holds for the paper-sized plan (no rendering needed).
    plan = plan_collection(CollectConfig(out_dir=Path("unused"), seed=0))
    assert len(plan.images) == 100 + 8 * 200 + 400 + 100
    assert not set(plan.train_scene_seeds) & set(plan.test_scene_seeds)


def test_a_row_rebuilds_its_view(tiny_dataset: Path) -> None:
    """The stored pose and scene seed reproduce the stored truth; offset_m is pose_for_offset's input."""
    rows, _ = load_manifest(tiny_dataset)
    row = next(r for r in rows if r["split"] == "train")
    from sim_world.rendering.camera import CameraConfig

    config = WorldConfig(camera=CameraConfig(width=96, height=96))
    with World(config, row["scene_seed"]) as world:
        assert world.scene.target_kind == row["target_kind"]
        o = row["offset_m"]
        position, yaw = world.scene.pose_for_offset(o["right_m"], o["up_m"], o["distance_m"], o["yaw_deg"])
        np.testing.assert_allclose(position, ned_to_enu(row["drone"]["position_ned_m"]), atol=1e-3)
        world.teleport(position, yaw)
        truth = world.target_truth()
        assert truth.centre_px == pytest.approx(tuple(row["centre_px"]), abs=0.05)


def test_worker_count_does_not_change_the_dataset(tiny_dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "two_workers"
    collect(CollectConfig(out_dir=out, workers=2, **TINY), progress=False)
    assert (out / "manifest.jsonl").read_bytes() == (tiny_dataset / "manifest.jsonl").read_bytes()
    for image in sorted((tiny_dataset / "images").iterdir()):
        assert (out / "images" / image.name).read_bytes() == image.read_bytes(), image.name


def test_collect_refuses_a_folder_that_holds_a_dataset(tiny_dataset: Path) -> None:
    with pytest.raises(DatasetError, match="already holds a dataset"):
        collect(CollectConfig(out_dir=tiny_dataset, workers=1, **TINY), progress=False)


def test_interrupted_collection_leaves_a_readable_dataset(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    real = collect_module.render_scenes
    calls = {"n": 0}

    def interrupted_after_one_job(job: tuple) -> list[dict]:
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return real(job)

    monkeypatch.setattr(collect_module, "render_scenes", interrupted_after_one_job)
    out = tmp_path / "cut"
    with pytest.raises(KeyboardInterrupt):
        collect(CollectConfig(out_dir=out, workers=1, **TINY), progress=False)
    rows, meta = load_manifest(out)
    assert meta["complete"] is False
    chunks = plan_collection(CollectConfig(out_dir=out, **TINY)).chunks()
    first_job = chunks[: collect_module.SCENES_PER_JOB]
    assert [r["id"] for r in rows] == [spec.image_id for chunk in first_job for spec in chunk]
    assert sum(meta["counts"].values()) == len(rows) > 0


def _write_minimal(tmp: Path, manifest_text: str) -> Path:
    (tmp / "images").mkdir(parents=True)
    meta = {"generator_version": "x", "seed": 0, "camera": {}, "scene_config": {}, "counts": {}}
    (tmp / "dataset.json").write_text(json.dumps(meta))
    (tmp / "manifest.jsonl").write_text(manifest_text)
    return tmp


def test_load_manifest_names_the_file_and_line_of_bad_input(tiny_dataset: Path, tmp_path: Path) -> None:
    with pytest.raises(DatasetError, match="no such dataset folder"):
        load_manifest(tmp_path / "nowhere")
    good = (tiny_dataset / "manifest.jsonl").read_text().splitlines()[0]

    corrupt = _write_minimal(tmp_path / "corrupt", good + "\n{not json\n")
    with pytest.raises(DatasetError, match=r"manifest\.jsonl:2: not valid JSON"):
        load_manifest(corrupt, check_images=False)

    row = json.loads(good)
    del row["centre_px"]
    missing = _write_minimal(tmp_path / "missing", json.dumps(row) + "\n")
    with pytest.raises(DatasetError, match=r"manifest\.jsonl:1: missing field 'centre_px'"):
        load_manifest(missing, check_images=False)

    no_image = _write_minimal(tmp_path / "no_image", good + "\n")
    with pytest.raises(DatasetError, match="is missing"):
        load_manifest(no_image)

    no_meta = _write_minimal(tmp_path / "no_meta", good + "\n")
    (no_meta / "dataset.json").unlink()
    with pytest.raises(DatasetError, match=r"dataset\.json: missing"):
        load_manifest(no_meta)
